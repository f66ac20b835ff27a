"""bench_radio_priority in small: each phase a few seconds over two namespaced hosts; the JSON
has each phase's live latencies, the live messages came through the rated link alone and
behind a paced bulk, and the bulk publisher's bytes crossed only where a phase has one. Skipped with one
line where namespaces cannot be made."""
from __future__ import annotations

import json
import os

import pytest

from benchmarks import radio_priority as bench
from saim_mesh.net import netns

pytestmark = pytest.mark.timeout(300)
WHY = netns.unavailable()


@pytest.mark.skipif(WHY is not None, reason=f"no namespaced hosts here: {WHY}")
def test_bench_radio_priority_writes_each_phase(tmp_path):
    out = tmp_path / "radio_priority.json"
    mine = f"{netns.BASE}{os.getpid()}-"   # other tests' hosts may be up beside this one
    before = {n for n in netns.namespaces() if n.startswith(mine)}
    assert bench.main(["--secs", "4", "--out-dir", str(tmp_path / "run"), "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    assert res["rate_kbit"] == 64 and set(res["phases"]) == set(bench.PHASES)
    for name, (bulk, *_) in bench.PHASES.items():
        ph = res["phases"][name]
        assert ph["live_latency_s"]["n"] == ph["live_received"], name
        if bulk is None or bulk < res["rate_kbit"]:   # behind a bulk that fills the link they may take longer
            assert ph["live_received"] > 0, name      # than a phase this short: what the benchmark shows
        assert (ph["bulk_kbit_s"] > 0) is (bulk is not None), name
    assert {n for n in netns.namespaces() if n.startswith(mine)} == before, "the hosts' namespaces were left behind"
