"""The alert-value score on battles nobody tuned for: for each seed, a battle drawn at
random (`generate --incidents random --sensors`: hostiles seen by simulated sensors with
noise, misses and false alarms, fused into tracks), its truth from the independent oracle, the EAs
and the naive detector (VOA off) scored against it. Writes the per-seed rows and the
summary (mean and worst recall, unwanted share, unwanted flash, detection delay p95,
reduction against the naive detector) as JSON, and with a commander in the loop (each
model of `evaluate.COMMANDERS`: what they saw, re-notifications and escalations included)
under `summary.armed`, and every type scored apart under `summary.by_type` (with the Fig. 1
new-opportunity category as one key of its own)."""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import tempfile
import time
from pathlib import Path

# recall on every seed, the unwanted share on every seed, flash over all seeds, reduction
# over all seeds together (reduction_worst is reported beside it); projections (issue 34):
# none raised at or after the violation it projects, and the median lead over every
# projection of every seed (evaluate._projections: to the oracle's `at`) at least this
TARGETS = {"recall": 1.0, "unwanted_share_max": 0.05, "unwanted_flash": 0, "reduction_min": 50.0,
           "after_the_fact": 0, "projection_lead_s_median_min": 30.0}


ARMED_TARGETS = {"unwanted_share_worst": 0.05, "unwanted_flash_total": 0}


def one(args: tuple) -> dict:
    seed, small, sensors, *rest = args
    commanders = rest[0] if rest else ()
    from ea_agent.domains.suo.generator import write

    from saim_mesh import scenario as S
    from saim_mesh.inprocess.evaluate import evaluate
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix=f"seed{seed}-") as d:
        gen = write(Path(d) / "sc", small=small, seed=seed, incidents="random", sensors=sensors)
        sc = S.load(Path(d) / "sc")
        res = evaluate(sc)
        armed = {}
        if commanders:   # the same battle with a commander in the loop, per model
            from saim_mesh.inprocess.evaluate import commander_view
            from saim_mesh.inprocess.runner import run
            plain = run(sc, res["owners"])
            for m in commanders:
                v = commander_view(sc, res["owners"], m, plain, sc.truth())
                armed[m] = {k: v[k] for k in ("alerts_shown", "renotifications", "escalations", "shown",
                                              "shown_per_commander_hour_worst", "unwanted_share", "unwanted_flash",
                                              "recall", "priorities_equal")}
    keep = ("recall", "incidents", "alerts", "unwanted", "unwanted_share", "unwanted_flash", "unwanted_repeats",
            "wrong_priority", "delay_s_median", "delay_s_p95", "naive_alerts", "reduction")
    row = {"seed": seed, **{k: res[k] for k in keep}, "naive_unwanted_share": res["naive"]["unwanted_share"],
           "events": gen["events"], "wall_s": round(time.perf_counter() - t0, 1),
           "projections": {**{k: res["projections"][k] for k in ("alerts", "false", "after_the_fact", "lead_s")},
                           "by_type": res["projections_by_type"]},
           "per_type": res["per_type"],
           "missed": [f"{m['owner']} {m['type']} {m['subjects']} t={m['at']}: {m['label']}" for m in res["missed"]],
           "unwanted_alerts": [f"{a['owner']} t={a['t']} {a['priority']} {a['type']} {a['subjects']}"
                               for a in res["unwanted_alerts"]], **({"armed": armed} if armed else {})}
    print(json.dumps({k: row[k] for k in ("seed", "recall", "incidents", "alerts", "unwanted_share", "unwanted_flash",
                                          "delay_s_p95", "reduction", "wall_s")}), flush=True)
    return row


OPPORTUNITY = "new-opportunity"   # Fig. 1's category, scored over all its types together too


def _figures(b: dict, recalls: list[float], shares: list[float]) -> dict:
    return {"incidents": b["incidents"], "missed": b["missed"],
            "recall": round(1 - b["missed"] / b["incidents"], 4) if b["incidents"] else None,
            "recall_worst": min(recalls) if recalls else None,
            "alerts": b["alerts"], "unwanted": b["unwanted"],
            "unwanted_share": round(b["unwanted"] / b["alerts"], 4) if b["alerts"] else 0.0,
            "unwanted_share_worst": max(shares) if shares else 0.0}


def by_type_summary(rows: list[dict]) -> dict:
    """Per alert or incident type over every seed (pooled recall and unwanted share, and the
    worst seed's), and the new-opportunity category as one more key: its types together."""
    from ea_agent.domains.suo.detect import CATEGORY
    groups: dict[str, list[str]] = {}
    for r in rows:
        for typ in r.get("per_type", {}):
            groups.setdefault(typ, [typ])
    groups[OPPORTUNITY] = sorted(t for t, c in CATEGORY.items() if c == OPPORTUNITY)
    out = {}
    for key, types in sorted(groups.items()):
        tot = {"incidents": 0, "missed": 0, "alerts": 0, "unwanted": 0}
        recalls, shares = [], []
        for r in rows:
            seed = {k: sum(r.get("per_type", {}).get(t, {}).get(k, 0) for t in types) for k in tot}
            for k in tot:
                tot[k] += seed[k]
            if seed["incidents"]:
                recalls.append(round(1 - seed["missed"] / seed["incidents"], 4))
            if seed["alerts"]:
                shares.append(round(seed["unwanted"] / seed["alerts"], 4))
        out[key] = _figures(tot, recalls, shares)
        if key == OPPORTUNITY:
            out[key]["types"] = types
    return out


def summarize(rows: list[dict]) -> dict:
    def col(k):
        return [r[k] for r in rows if r[k] is not None]
    s = {"seeds": len(rows),
         "recall_mean": round(sum(col("recall")) / len(rows), 4), "recall_worst": min(col("recall")),
         "unwanted_share_mean": round(sum(col("unwanted_share")) / len(rows), 4),
         "unwanted_share_worst": max(col("unwanted_share")),
         "unwanted_flash_total": sum(col("unwanted_flash")),
         "delay_s_p95_worst": max(col("delay_s_p95"), default=None),
         "delay_s_p95_mean": round(sum(col("delay_s_p95")) / max(1, len(col("delay_s_p95"))), 1),
         "reduction_mean": round(sum(col("reduction")) / len(rows), 1), "reduction_worst": min(col("reduction")),
         # all naive alerts over all our alerts: the per-seed ratio is small on a quiet battle,
         # where the naive detector has little to repeat
         "reduction_total": round(sum(col("naive_alerts")) / max(1, sum(col("alerts"))), 1),
         "naive_unwanted_share_mean": round(sum(col("naive_unwanted_share")) / len(rows), 4),
         "incidents_total": sum(col("incidents")), "alerts_total": sum(col("alerts"))}
    # projected violations over every seed: how far ahead of the violation (the oracle's
    # `at`) each was raised, and how many came at or after it
    leads = sorted(x for r in rows for x in r.get("projections", {}).get("lead_s", ()))
    s["projections_total"] = sum(r.get("projections", {}).get("alerts", 0) for r in rows)
    s["projections_false_total"] = sum(r.get("projections", {}).get("false", 0) for r in rows)
    s["after_the_fact_total"] = sum(r.get("projections", {}).get("after_the_fact", 0) for r in rows)
    s["projection_lead_s_median"] = leads[len(leads) // 2] if leads else None
    s["projection_lead_s_min"] = leads[0] if leads else None
    by_type: dict[str, dict] = {}
    for r in rows:
        for typ, v in r.get("projections", {}).get("by_type", {}).items():
            b = by_type.setdefault(typ, {"alerts": 0, "false": 0, "after_the_fact": 0, "lead_s": []})
            for k in ("alerts", "false", "after_the_fact"):
                b[k] += v[k]
            b["lead_s"] += v["lead_s"]
    s["projections_by_type"] = {}
    for typ, b in sorted(by_type.items()):
        ls = sorted(b.pop("lead_s"))
        s["projections_by_type"][typ] = {**b, "lead_s_median": ls[len(ls) // 2] if ls else None,
                                         "lead_s_min": ls[0] if ls else None}
    s["by_type"] = by_type_summary(rows)
    models = sorted({m for r in rows for m in r.get("armed", {})})
    if models:   # what each modelled commander saw, over every seed
        s["armed"] = {}
        for m in models:
            vs = [r["armed"][m] for r in rows if m in r.get("armed", {})]
            s["armed"][m] = {
                "unwanted_share_worst": max(v["unwanted_share"] for v in vs),
                "unwanted_share_mean": round(sum(v["unwanted_share"] for v in vs) / len(vs), 4),
                "unwanted_flash_total": sum(v["unwanted_flash"] for v in vs),
                "shown_per_commander_hour_worst": max(v["shown_per_commander_hour_worst"] for v in vs),
                "shown_per_commander_hour_mean": round(sum(v["shown_per_commander_hour_worst"] for v in vs)
                                                       / len(vs), 1),
                "renotifications_total": sum(v["renotifications"] for v in vs),
                "escalations_total": sum(v["escalations"] for v in vs),
                "priorities_equal": all(v["priorities_equal"] for v in vs),
                "recall_worst": min(v["recall"] for v in vs)}
        s["armed_targets"] = ARMED_TARGETS
    s["targets"] = TARGETS
    s["met"] = {"recall": s["recall_worst"] >= TARGETS["recall"],
                "unwanted_share": s["unwanted_share_worst"] <= TARGETS["unwanted_share_max"],
                "unwanted_flash": s["unwanted_flash_total"] == TARGETS["unwanted_flash"],
                "reduction": s["reduction_total"] >= TARGETS["reduction_min"],
                "after_the_fact": s["after_the_fact_total"] == TARGETS["after_the_fact"],
                "projection_lead": (s["projection_lead_s_median"] is not None
                                    and s["projection_lead_s_median"] >= TARGETS["projection_lead_s_median_min"])}
    opp = s["by_type"].get(OPPORTUNITY)
    s["met"]["new_opportunity"] = (opp is not None and opp["incidents"] > 0 and opp["recall"] >= TARGETS["recall"]
                                   and opp["unwanted_share"] <= TARGETS["unwanted_share_max"])
    for m, v in s.get("armed", {}).items():
        s["met"][f"armed_{m}"] = (v["unwanted_share_worst"] <= ARMED_TARGETS["unwanted_share_worst"]
                                  and v["unwanted_flash_total"] == ARMED_TARGETS["unwanted_flash_total"]
                                  and v["priorities_equal"])
    return s


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="evaluate_seeds", description=__doc__)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--full", action="store_true", help="full-size battalion (default: the small variant)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--true-tracks", action="store_true",
                    help="hostile tracks at their true positions (default: simulated sensors through fusion)")
    ap.add_argument("--commanders", default="none,slow,diligent",
                    help="commander models to run armed per seed, comma-separated ('' for none)")
    ap.add_argument("--out", default="bench/results/alert_value.json")
    a = ap.parse_args(argv)
    if a.seeds < 1 or a.jobs < 1:
        ap.error("--seeds and --jobs must be at least 1")
    commanders = tuple(m for m in a.commanders.split(",") if m)
    from saim_mesh.inprocess.evaluate import COMMANDERS
    for m in commanders:
        if m not in COMMANDERS:
            ap.error(f"--commanders: unknown model {m!r} (known: {', '.join(COMMANDERS)})")
    work = [(s, not a.full, not a.true_tracks, commanders) for s in range(a.first, a.first + a.seeds)]
    t0 = time.perf_counter()
    with mp.get_context("spawn").Pool(a.jobs) as pool:
        rows = pool.map(one, work, chunksize=1)
    out = {"summary": summarize(rows), "size": "full" if a.full else "small",
           "tracks": "true positions" if a.true_tracks else "simulated sensors, fused near their source",
           "wall_s": round(time.perf_counter() - t0),
           "note": ("each seed is a battle drawn at random (ea_agent/domains/suo/random_battle.py); truth from "
                    "the oracle (ea_agent/domains/suo/oracle/, which imports nothing else of ea_agent); scored by "
                    "saim_mesh/inprocess/evaluate.py: recall per incident in its window, delay from when it happened, unwanted = "
                    "matches nothing, repeats the same story without a 1.25x severity change, or wrong priority"),
           "rows": rows}
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out["summary"], indent=1))
    return 0 if all(out["summary"]["met"].values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
