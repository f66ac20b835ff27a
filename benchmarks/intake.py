"""The EA peer's own work, without Zenoh: the real `Peer` receiving the replay's stream
for one unit (its batches and singles, routed to its coarse subscriptions by key
expression, the situation store answering its catch-ups) and working its clock ticks,
against the in-process EA on the same scenario in the same run.

`bench_mesh` measures a live peer, where two processes and Zenoh's threads share two
noisy cores; this takes them away, so what is left is what the peer's Python costs
beside its EA: receiving (decode, checks, hold), tick bookkeeping and re-registration.
Each pass is a fresh peer; the best of `--repeat` passes is reported, per stage, in
main-thread CPU seconds. Results: bench/results/intake.json."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from saim_mesh import scenario as S
from .ea import feed
from saim_mesh.offline import run, stream
from saim_mesh.runner import config_for, make_ea

from . import ROOT


def _same(a) -> tuple:
    """What makes two alerts the same alert (`alertlog.alert_key`)."""
    return (a.t, a.owner, a.type, tuple(a.subjects), a.message, a.priority)


def one_pass(sc, unit: str, chunks) -> dict:
    """A fresh peer through the whole stream: CPU seconds per stage and what it took in."""
    p, cpu = run(sc, unit, chunks)
    return {"cpu_s": cpu, "alerts": [_same(a) for a in p.ea.alerts],
            "messages": p.ea.n_in, "flow": dict(p.flow),
            "keys": {"held": len(p.facts), "sweeps": p.facts.epoch,   # the per-key cache at the end
                     "oldest_sweep_heard": min((f.seen for f in p.facts.values()), default=None)}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion"))
    ap.add_argument("--unit", default="BN")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "intake.json"))
    a = ap.parse_args(argv)
    sc = S.load(a.scenario)
    chunks = stream(sc)
    passes, inproc = [], []
    for _ in range(a.repeat):   # interleaved: both see the same moments of this machine
        passes.append(one_pass(sc, a.unit, chunks))
        ea = make_ea(sc, a.unit, config_for(sc, a.unit, None), sinks=[])
        k = time.thread_time()
        feed(ea, sc)
        inproc.append((time.thread_time() - k, [_same(x) for x in ea.alerts]))
    best = {k: min(x["cpu_s"][k] for x in passes) for k in passes[0]["cpu_s"]}
    peer_s = sum(best.values())
    in_s = min(t for t, _ in inproc)
    res = {
        "scenario": Path(a.scenario).name, "unit": a.unit, "repeat": a.repeat,
        "events": len(sc.events), "messages": passes[0]["messages"], "flow": passes[0]["flow"],
        "keys": passes[0]["keys"],
        "peer_cpu_s": {k: round(v, 3) for k, v in best.items()}, "peer_s": round(peer_s, 3),
        "in_process_s": round(in_s, 3), "share_of_in_process": round(in_s / peer_s, 3),
        "beside_the_ea_s": round(peer_s - in_s, 3),
        "alerts": len(passes[0]["alerts"]),
        "alerts_equal_in_process": all(x["alerts"] == inproc[0][1] for x in passes),
        "note": "no Zenoh, no second process: the peer's Python beside its EA (best of the passes, "
                "main-thread CPU); bench_mesh measures the live peer",
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))
    return 0 if res["alerts_equal_in_process"] else 1


if __name__ == "__main__":
    sys.exit(main())
