"""docs/benchmarks.md, generated from bench/results/*.json: one row per results file (what
it measures, its target, the latest figure, the script that writes it). The page is never
edited by hand, so it cannot go stale: `tests/test_bench_page.py` regenerates it and fails
when the committed page differs, or when a results file has no row here.

    python -m benchmarks.page            # write docs/benchmarks.md
    python -m benchmarks.page --check    # exit 1 if it is stale
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from . import RESULTS, ROOT

PAGE = ROOT / "docs" / "benchmarks.md"


def get(d: dict, path: str):
    """`a.b.c` of nested dicts, or None where a key is missing."""
    for k in path.split("."):
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def fig(d: dict, *parts: tuple[str, str]) -> str:
    """`label value` for each (label, key path) present in `d`, joined."""
    out = []
    for label, path in parts:
        v = get(d, path)
        if v is not None:
            out.append(f"{label} {_show(v)}")
    return "; ".join(out) or "(none of its figures found)"


def _show(v) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:,.3g}" if abs(v) < 100 else f"{v:,.0f}"
    if isinstance(v, int):
        return f"{v:,}"
    if isinstance(v, dict) and v and all(isinstance(x, bool) for x in v.values()):
        missed = [k for k, x in v.items() if not x]
        return "all yes" if not missed else "no: " + ", ".join(missed)
    if isinstance(v, dict) and "p99" in v:
        return f"p99 {_show(v['p99'])}"
    if isinstance(v, dict) and "max" in v:
        return f"max {_show(v['max'])}"
    return str(v)


@dataclass(frozen=True)
class Row:
    script: str
    what: str
    target: str
    figure: Callable[[dict], str]


def _hosts(d: dict) -> str:
    return fig(d, ("link kbit/s", "link_rate_kbps"), ("speed", "speed"), ("EA peers", "ea_peers"),
               ("alerts equal in-process", "alerts_equal_in_process"), ("met by part", "targets_met_by_part"),
               ("targets met", "targets_met"))


HOSTS = Row("scripts/bench_hosts", "the brigade on namespaced hosts over rate-limited links: fault-free, a cut "
            "link, a killed host", "alerts equal to in-process, late alerts after heal, none lost", _hosts)

ROWS: dict[str, Row] = {
    "alert_value": Row("scripts/evaluate_seeds", "the EAs scored against the oracle on 20 random battles "
                       "(recall, unwanted share, delay, FLASH)", "recall 1.0, < 10 % unwanted, no unwanted FLASH",
                       lambda d: fig(d, ("seeds", "summary.seeds"), ("recall worst", "summary.recall_worst"),
                                     ("unwanted worst", "summary.unwanted_share_worst"),
                                     ("unwanted FLASH", "summary.unwanted_flash_total"),
                                     ("delay p95 worst s", "summary.delay_s_p95_worst"),
                                     ("new-opportunity recall", "summary.by_type.new-opportunity.recall"),
                                     ("shown/h unacknowledged worst", "summary.armed.none.shown_per_commander_hour_worst"),
                                     ("met", "summary.met"))),
    "console": Row("scripts/bench_console", "the commander's console on the battalion mesh: alerts and notices "
                   "shown, render latency, first paint", "what the EAs raised, render p99 <= 100 ms",
                   lambda d: fig(d, ("alerts on page", "alerts_page"), ("render", "render_latency_ms"),
                                 ("first paint ms", "first_paint_ms"), ("met", "met"))),
    "deployment_rates": Row("scripts/deployment_rates.py", "what each radio link of a division would carry, "
                            "scaled from the measured battalion", "fits the links of docs/history/deployment-notes.md",
                            lambda d: fig(d, ("control tick bytes", "control.tick_bytes"))),
    "ea": Row("scripts/bench_ea", "one EA in process on the battalion stream, per fact-batch size",
              ">= 100,000 events/s", lambda d: fig(d, ("events/s", "events_per_s"),
                                                    ("target", "target_events_per_s"),
                                                    ("best batch", "best_fact_batch"))),
    "fusion": Row("scripts/bench_fusion", "the fusion node's tracker against Stone Soup's on the same hits",
                  "at least Stone Soup's accuracy, more hits per CPU second",
                  lambda d: fig(d, ("Stone Soup compared", "stonesoup"))),
    "hosts": HOSTS,
    "link": Row("scripts/bench_link", "the emulated radio link: throughput and delay/loss fidelity",
                "delay and loss as set", lambda d: fig(d, ("MB/s", "throughput.mb_per_s"))),
    "live": Row("scripts/bench_live", "the battalion live at 1x, one source killed half way",
                "report-to-alert p99 <= 100 ms, a lost source told within its silence limit + 1 s",
                lambda d: fig(d, ("report-to-alert ms", "report_to_alert_ms"),
                              ("lost source told s", "killed_source_alert_s_max"),
                              ("journals replay equal", "journal_replay_equal"), ("met", "targets_met"))),
    "mesh": Row("scripts/bench_mesh", "EA peers on the battalion and battalion-sensors: CPU per message against "
                "the in-process EA fed the same messages, memory, alerts", "see its `targets`",
                lambda d: fig(d, ("EA CPU ratio", "ea_cpu_ratio"), ("peak PSS MB", "live_pss_mb_max"),
                              ("alerts equal", "live_alerts_equal_in_process"))),
    "partition": Row("scripts/bench_partition", "a router link of the brigade cut and healed",
                     "the uncut side on time, every alert after the heal, none twice",
                     lambda d: fig(d, ("on time (uncut)", "on_time_share_uncut"),
                                   ("equal after heal", "alerts_equal_after_heal"), ("late", "late"),
                                   ("duplicates", "duplicates"), ("met", "targets_met"))),
    "radio": Row("scripts/bench_radio", "kbit/s on each router link direction of the full brigade at 1x",
                 "every direction <= 25 kbit/s plain (issue 50)",
                 lambda d: fig(d, ("worst kbit/s plain", "worst_direction_kbps_1x_plain"),
                               ("worst compressed", "worst_direction_kbps_1x_compressed"),
                               ("fits the link", "fits_link_1x_plain"))),
    "radio_priority": Row("scripts/bench_radio_priority", "alerts' latency on a full radio link, by priority",
                          "urgent first", lambda d: fig(d, ("link kbit/s", "rate_kbit"))),
    "scale": Row("scripts/bench_scale", "the brigade through an EA peer per unit and a router per battalion "
                 "at max speed",
                 ">= 10x real time, <= 40 MB PSS per EA peer, alerts equal in-process",
                 lambda d: fig(d, ("x real time", "times_real_time"), ("EA peer PSS MB", "ea_peer_pss_mb"),
                               ("alerts equal", "alerts_equal_in_process"))),
    "sign": Row("scripts/bench_sign", "Ed25519 signing and verification per message, and the gate's cost",
                "signed orders cheap beside the EA", lambda d: fig(d, ("sign us", "sign_cost_us"),
                                                                   ("verify us", "verify_cost_us"))),
    "soak": Row("scripts/soak", "the live mesh under crashes, a source held down, junk and forged directives",
                "no alert lost or twice, equal to the fault-free run, memory flat",
                lambda d: fig(d, ("lost", "alerts_lost"), ("twice", "duplicates"),
                              ("equal fault-free", "alerts_equal_fault_free"), ("restarts", "restarts"))),
    "tak": Row("scripts/bench_tak", "Cursor-on-Target encoding of the picture and alerts", "faster than the mesh "
               "produces them", lambda d: fig(d, ("alerts CoT/s", "alerts.events_per_s"))),
    "tests": Row("scripts/bench_tests", "the test suite as CI runs it", "wall <= 1,200 s, every test passing",
                 lambda d: fig(d, ("tests", "tests"), ("passed", "passed"), ("skipped", "skipped"),
                               ("wall s", "wall_s"), ("met", "met"))),
    "uv": Row("scripts/bench_uv", "the robot team's EAs: messages per second against the paper's rate",
              "above the paper's rate", lambda d: fig(d, ("robot EA x paper rate", "robot_ea_x_paper_rate"),
                                                      ("team EA x its rate", "team_ea_x_its_rate"))),
}


def row_for(stem: str) -> Row | None:
    """Its own row, or its family's (`hosts_cut_1.5x` is a variant of `hosts`)."""
    return ROWS.get(stem) or ROWS.get(stem.split("_", 1)[0] if stem.startswith("hosts_") else "")


def render(results: Path = RESULTS) -> str:
    lines = ["# Benchmarks", "",
             "Generated by `python -m benchmarks.page` from `bench/results/*.json`; do not edit by hand.",
             "Each figure is the latest committed run's; the results file holds the rest (and the machine).", "",
             "| results file | script | what it measures | target | latest figures |",
             "|---|---|---|---|---|"]
    for p in sorted(results.glob("*.json")):
        r = row_for(p.stem)
        if r is None:
            raise KeyError(f"{p.name}: no row in benchmarks/page.py ROWS: say what it measures and its target")
        try:
            d = json.loads(p.read_text(encoding="utf-8"))
        except ValueError as e:
            raise ValueError(f"{p.name}: not JSON ({e})") from None
        figure = r.figure(d) if isinstance(d, dict) else "(not an object)"
        lines.append(f"| `{p.name}` | `{r.script}` | {r.what} | {r.target} | {figure} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="write (or --check) docs/benchmarks.md from bench/results/")
    ap.add_argument("--check", action="store_true", help="exit 1 if the committed page differs")
    a = ap.parse_args(argv)
    try:
        text = render()
    except (KeyError, ValueError) as e:
        print(f"benchmarks.page: {e.args[0]}", file=sys.stderr)
        return 2
    if a.check:
        if not PAGE.exists() or PAGE.read_text(encoding="utf-8") != text:
            print(f"{PAGE.relative_to(ROOT)} is stale: run python -m benchmarks.page", file=sys.stderr)
            return 1
        return 0
    PAGE.write_text(text, encoding="utf-8")
    print(f"wrote {PAGE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
