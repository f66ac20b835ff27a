"""Events per second of one EA over the battalion stream, in process, per fact-batch size.

Baselines measured in the same run: the bare loop over the events (the floor) and
msgpack decoding of the same stream (what a mesh peer pays before the EA sees it).
"""
from __future__ import annotations

import argparse
import cProfile
import io
import json
import platform
import pstats
import time
from pathlib import Path

from ea_agent.core.config import load_config
from ea_agent.domains.suo import make_ea

from saim_mesh.protocol import messages
from saim_mesh import scenario as scenarios

from . import ROOT


def feed(ea, sc) -> float:
    """Seconds for an EA to take every event of the scenario, start to finish."""
    ea.start(0.0)
    submit = ea.submit
    t0 = time.perf_counter()
    for ev in sc.events:
        submit(ev)
    ea.finish(sc.duration_s)
    return time.perf_counter() - t0


def one_run(sc, owner: str, batch: int) -> tuple[float, object]:
    ea = make_ea(sc, owner, load_config(None, owner, {"manager": {"fact_batch": batch}}))
    return feed(ea, sc), ea


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion"))
    p.add_argument("--owner", default="BN")
    p.add_argument("--batches", default="1,8,16,32,64,128")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--out", default=str(ROOT / "bench" / "results" / "ea.json"))
    a = p.parse_args(argv)
    sc = scenarios.load(a.scenario)
    n = len(sc.events)
    t0 = time.perf_counter()
    for _ in sc.events:
        pass
    loop_s = time.perf_counter() - t0
    wire = [messages.encode(e) for e in sc.events]
    t0 = time.perf_counter()
    for w in wire:
        messages.decode(w)
    decode_s = time.perf_counter() - t0
    results = {}
    for b in [int(x) for x in a.batches.split(",")]:
        best = min(one_run(sc, a.owner, b)[0] for _ in range(a.repeat))
        results[b] = round(n / best)
        print(f"fact_batch {b:4d}: {results[b]:>9,} events/s")
    best_b = max(results, key=results.get)
    _, ea = one_run(sc, a.owner, best_b)
    prof = cProfile.Profile()
    prof.enable()
    one_run(sc, a.owner, best_b)
    prof.disable()
    buf = io.StringIO()
    pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(12)
    text = buf.getvalue().replace(str(ROOT) + "/", "")
    top = [line.strip() for line in text.splitlines() if line.strip()[:1].isdigit()][:12]
    res = {
        "scenario": sc.name, "owner": a.owner, "events": n, "events_per_s": results[best_b],
        "best_fact_batch": best_b, "events_per_s_by_batch": results,
        "facts_passed_by_watchman": ea.stats["facts"], "epochs": ea.stats["epochs"], "alerts": len(ea.alerts),
        "epoch_s": ea.epoch_s, "baseline_loop_events_per_s": round(n / loop_s),
        "baseline_msgpack_decode_per_s": round(n / decode_s),
        "target_events_per_s": 100_000, "profile_top_tottime": top,
        "python": platform.python_version(), "machine": platform.machine(),
    }
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps({k: res[k] for k in ("events_per_s", "best_fact_batch", "baseline_msgpack_decode_per_s")}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
