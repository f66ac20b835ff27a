"""A cut radio link on the live mesh (issue 31): the brigade through `mesh up --topology`
(a router per battalion command post and one at brigade, linked through emulated radio
links), secure, one source per command post paced at `--speed` x real time, no replay and
no global tick. Run twice in one go: fault-free, then with one battalion-brigade link cut
for `--cut-s` seconds of scenario time and healed. Writes bench/results/partition.json:

- `frozen_epochs_uncut`: epochs that EAs whose sources all lie on their own side of the
  cut released late (more than `frozen_s` wall seconds after the sources' shared clock
  passed them and later than in the fault-free run): a cut must stop only what depends on it;
- `on_time_share_uncut`: of those EAs' alerts, the share raised within one epoch (scenario
  time) of when the fault-free run raised them;
- `lost_alert_s_max`: from the cut to the system-problem alert naming a source across it,
  the worst over the EAs that depend on one (target `source_silence_s` + 2);
- `alerts_equal_after_heal`: every EA's final alerts as shown to its commander (system
  problems apart, and what it concluded about a lost source's units on a partial picture,
  logged inhibited by the loss: `inhibited_during_loss`) equal the fault-free run's; `late`
  counts those raised when the source came back (the EA rebuilt from its journal), marked
  with when they were due; `duplicates`: alerts shown twice by one EA (target 0).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import threading
import time
from collections import Counter
from pathlib import Path

from .stats import percentiles

from . import ROOT


def _key(a: dict) -> tuple:
    return (a["t"], a["type"], tuple(a["subjects"]), a["message"])


def _shown(a: dict) -> bool:
    """An alert the commander is shown: not a system problem, not inhibited (an EA that lost
    a source inhibits what it concludes about that source's units on a partial picture)."""
    return a["category"] != "system-problem" and "inhibited_by" not in a["details"]


def _alerts(path: Path) -> list[dict]:
    try:
        return [json.loads(x) for x in open(path, encoding="utf-8") if x.strip()]
    except FileNotFoundError:
        return []


def run(scenario: str, out_dir: Path, speed: float, link_name: str | None, cut_from: float, cut_s: float,
        timeout: float) -> tuple[dict, dict]:
    from saim_mesh.live.up import up
    cut: dict = {}

    def on_started(sup, paced_start) -> None:
        if link_name is None:
            return

        def cutter():
            p = sup.procs[link_name]
            time.sleep(max(0.0, paced_start + cut_from / speed - time.time()))
            os.kill(p.pid, signal.SIGUSR1)
            cut["cut_wall"] = time.time()
            print(f"bench: cut {link_name} at event time {(cut['cut_wall'] - paced_start) * speed:.0f}", flush=True)
            time.sleep(max(0.0, paced_start + (cut_from + cut_s) / speed - time.time()))
            os.kill(p.pid, signal.SIGUSR2)
            cut["heal_wall"] = time.time()
            print(f"bench: healed {link_name} at event time {(cut['heal_wall'] - paced_start) * speed:.0f}", flush=True)
        threading.Thread(target=cutter, daemon=True).start()

    res = up(scenario, None, out_dir, speed=str(speed), show=False, topology="derive", link={"delay_ms": 0.0},
             on_started=on_started, timeout=timeout)
    return res, cut


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench_partition", description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", help="default: brigade-small, generated on demand into out/scenarios")
    ap.add_argument("--speed", type=float, default=5.0)
    ap.add_argument("--cut", default="r-1BN", help="the lower router of the link cut (to the router above it)")
    ap.add_argument("--cut-from", type=float, default=300.0, help="scenario second the link is cut")
    ap.add_argument("--cut-s", type=float, default=600.0, help="scenario seconds it stays cut")
    ap.add_argument("--frozen-s", type=float, default=4.0,
                    help="wall seconds late an epoch must be released to count as frozen (the silence is 10)")
    ap.add_argument("--out-dir", default="out/bench-partition")
    ap.add_argument("--analyze-only", action="store_true",
                    help="no runs: the figures from the runs already in --out-dir (cut at its scheduled instant)")
    ap.add_argument("--out", default="bench/results/partition.json")
    a = ap.parse_args(argv)
    from saim_mesh import scenario as S
    from saim_mesh.net import topology as T
    from saim_mesh.live.up import cp_sources
    from saim_mesh.ondemand import ensure
    from saim_mesh.inprocess.runner import config_for, run as run_in_process
    scenario = a.scenario or str(ensure("brigade-small", ROOT / "out" / "scenarios"))
    sc = S.load(scenario)
    topo = T.derive(sc.taskorg)
    ups = {lo: up for lo, up in topo.links()}
    if a.cut not in ups:
        ap.error(f"--cut {a.cut}: not the lower end of a router link ({', '.join(sorted(ups))})")
    link = (a.cut, ups[a.cut])
    below = topo.side(link)
    side = lambda who: topo.router_of(who, sc.taskorg) in below   # noqa: E731  True: the cut-off side
    silence = float(config_for(sc, sc.taskorg.root)["mesh"]["source_silence_s"])
    timeout = sc.duration_s / a.speed + 900
    out_dir = Path(a.out_dir)
    t0 = time.monotonic()
    if a.analyze_only:
        free, cutr = (json.loads((out_dir / d / "summary.json").read_text()) for d in ("free", "cut"))
        cut = {"cut_wall": cutr["paced_start"] + a.cut_from / a.speed}
    else:
        free, _ = run(scenario, out_dir / "free", a.speed, None, 0, 0, timeout)
        cutr, cut = run(scenario, out_dir / "cut", a.speed, f"link-{link[0]}-{link[1]}", a.cut_from, a.cut_s,
                        timeout)
    eas = run_in_process(sc, free["units"])
    inproc = {ea.owner: sorted(_key(x.to_json_dict()) for x in ea.alerts) for ea in eas}

    ep = 2.0
    src_side = {n: side(n.removeprefix("cp.")) for n in cp_sources(sc)}
    uncut, across, frozen, on_time, late, dups, unequal, lost_s = [], [], 0, [0, 0], 0, 0, {}, {}
    free_equal_inproc = {}
    lag_uncut = []
    inhibited = 0
    for u in free["units"]:
        fs, cs = free["peers"].get(u), cutr["peers"].get(u)
        fa = [x for x in _alerts(out_dir / "free" / f"{u}.jsonl") if _shown(x)]
        ca_all = _alerts(out_dir / "cut" / f"{u}.jsonl")
        ca = [x for x in ca_all if _shown(x)]
        inhibited += sum(1 for x in ca_all if x["category"] != "system-problem" and "inhibited_by" in x["details"])
        free_equal_inproc[u] = sorted(map(_key, fa)) == inproc.get(u)
        c = Counter(map(_key, ca))
        dups += sum(n - 1 for n in c.values() if n > 1)
        late += sum(1 for x in ca if x["details"].get("late"))
        if sorted(set(map(_key, ca))) != sorted(set(map(_key, fa))):
            unequal[u] = {"missing": len(set(map(_key, fa)) - set(map(_key, ca))),
                          "extra": len(set(map(_key, ca)) - set(map(_key, fa)))}
        if fs is None or cs is None:
            unequal.setdefault(u, {})["no_summary"] = True
            continue
        deps = cs.get("depends", [])
        if all(src_side[d] == side(u) for d in deps):
            uncut.append(u)
            fe, ce = fs["timeline"]["epochs_wall"], cs["timeline"]["epochs_wall"]
            for k, w in enumerate(ce):
                lag = w - (cutr["paced_start"] + (k + 1) * ep / a.speed)
                lag_free = fe[k] - (free["paced_start"] + (k + 1) * ep / a.speed) if k < len(fe) else 0.0
                lag_uncut.append(lag)
                if lag > a.frozen_s and lag > lag_free + ep / a.speed:
                    frozen += 1
            raised_free = {(x[0], x[1], tuple(x[2])): x[3] for x in fs["timeline"]["alerts_wall"]}
            for x in cs["timeline"]["alerts_wall"]:
                k = (x[0], x[1], tuple(x[2]))
                if k not in raised_free:
                    continue
                on_time[1] += 1
                when_cut = (x[3] - cutr["paced_start"]) * a.speed
                when_free = (raised_free[k] - free["paced_start"]) * a.speed
                on_time[0] += when_cut <= when_free + ep
        else:
            across.append(u)
            gone = [x for x in ca_all if x["category"] == "system-problem" and x["details"].get("event") == "source-lost"
                    and src_side.get(x["subjects"][0]) != side(u)]
            if gone and "cut_wall" in cut:
                lost_s[u] = round(min(x["details"]["declared_wall"] for x in gone) - cut["cut_wall"], 2)
    worst = max(lost_s.values(), default=None)
    out = {"scenario": Path(scenario).name, "speed": a.speed, "secure": cutr.get("secure"),
           "cut": f"{link[0]}-{link[1]}", "cut_from_t": a.cut_from, "cut_s": a.cut_s,
           "peers": len(free["units"]), "sources": sorted(src_side), "sources_cut_off": sorted(n for n, s in src_side.items() if s),
           "uncut_eas": len(uncut), "eas_depending_across": len(across),
           "frozen_epochs_uncut": frozen, "frozen_s": a.frozen_s,
           "uncut_epoch_lag_s": percentiles(lag_uncut, 3),
           "on_time_share_uncut": round(on_time[0] / on_time[1], 4) if on_time[1] else None,
           "on_time_alerts_uncut": on_time[1],
           "lost_alert_s": lost_s, "lost_alert_s_max": worst, "source_silence_s": silence,
           "alerts_equal_after_heal": not unequal, "unequal": unequal, "late": late, "duplicates": dups,
           "inhibited_during_loss": inhibited,
           "fault_free_equal_in_process": all(free_equal_inproc.values()),
           "fault_free_unequal": sorted(u for u, ok in free_equal_inproc.items() if not ok),
           "targets": {"frozen_epochs_uncut": 0, "on_time_share_uncut": 0.99, "lost_alert_s_max": silence + 2,
                       "alerts_equal_after_heal": True, "duplicates": 0},
           "wall_s": round(time.monotonic() - t0, 1)}
    out["targets_met"] = (frozen == 0 and (out["on_time_share_uncut"] or 0) >= 0.99 and worst is not None
                          and worst <= silence + 2 and not unequal and dups == 0)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out, indent=1))
    return 0 if out["targets_met"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
