"""bench_intake drives the real Peer's receive and tick path without Zenoh: on the small
scenario that peer raises exactly the in-process EA's alerts, and the bench says so."""
from __future__ import annotations

import json
from pathlib import Path

from benchmarks import intake as bench_intake
from saim_mesh import scenario as S

SMALL = Path(__file__).resolve().parents[1] / "scenarios" / "small"


def test_the_offline_peer_raises_the_in_process_alerts(tmp_path):
    sc = S.load(SMALL)
    top = sc.taskorg.root
    out = tmp_path / "intake.json"
    assert bench_intake.main(["--scenario", str(SMALL), "--unit", top, "--repeat", "1", "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    assert res["alerts_equal_in_process"] is True
    assert res["alerts"] > 0 and res["messages"] > 0
    assert res["flow"]["entries"] > 0 and res["flow"]["batches"] > 0   # the batch path was taken
    assert set(res["peer_cpu_s"]) == {"receive", "ticks", "interest"}


def test_what_the_stream_loses_the_peer_never_hears(tmp_path, monkeypatch):
    """The peer hears only the stream it is given (no second path feeds it)."""
    sc = S.load(SMALL)
    top = sc.taskorg.root
    chunks = bench_intake.stream(sc)
    # drop every batched report of one group: the peer never hears those units move
    victim = next(k for c in chunks for k, _, att in c[0] if att is None and "/pos/" in k)
    cut = [([x for x in samples if x[0] != victim], added, tick) for samples, added, tick in chunks]
    full = bench_intake.one_pass(sc, top, chunks)
    lossy = bench_intake.one_pass(sc, top, cut)
    assert lossy["flow"]["entries"] < full["flow"]["entries"]
    assert lossy["messages"] < full["messages"]


def test_the_peer_sweeps_its_key_cache_on_scenario_time_and_keeps_only_keys_heard_since():
    """Once a minute of scenario time the peer forgets the keys not heard since the sweep
    before: at the end its cache holds only keys heard in the last two minutes."""
    sc = S.load(SMALL)
    top = sc.taskorg.root
    chunks = bench_intake.stream(sc)
    res = bench_intake.one_pass(sc, top, chunks)["keys"]
    assert res["sweeps"] == int(sc.duration_s // 60)   # at t = 60, 120, ... of the scenario
    # every key held was heard since the sweep before the last one: nothing older survives
    assert res["held"] > 0 and res["oldest_sweep_heard"] >= res["sweeps"] - 1
    never = bench_intake.one_pass(sc, top, chunks)
    assert never["keys"] == res   # the same stream, the same cache: scenario time, not wall time
