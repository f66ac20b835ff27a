"""bench_hosts in small: the small scenario over its four namespaced hosts (BN, A, B, C), secure,
64 kbit/s on each company's link, the sources to event time 300 at 25x, 15 s from starting the
hosts to event time 0 (their EA peers are ready well before), the fault-free run only: the
JSON has the keys the issue names, the peers' alerts were compared with the in-process
run's (and equal), each rated link carried bytes both ways. Skipped with one line where
namespaces cannot be made."""
from __future__ import annotations

import json

import pytest

from benchmarks import hosts as bench_hosts
from saim_mesh.net import netns

from .conftest import SMALL

pytestmark = [pytest.mark.timeout(600), pytest.mark.solo]   # wall-clock silence limits: the machine to itself
WHY = netns.unavailable()


@pytest.mark.skipif(WHY is not None, reason=f"no namespaced hosts here: {WHY}")
def test_bench_hosts_writes_its_keys_and_compares_alerts(tmp_path):
    out = tmp_path / "hosts.json"
    code = bench_hosts.main(["--scenario", str(SMALL), "--until", "300", "--speed", "25", "--lead", "15",
                             "--runs", "free", "--out-dir", str(tmp_path / "run"), "--out", str(out)])
    res = json.loads(out.read_text())
    assert code == 1   # four hosts and no cut or kill: not the done-when's targets
    for k in ("hosts", "ea_peers", "link_rate_kbps", "times_real_time", "alerts_equal_in_process", "links", "cut",
              "host_kill", "targets", "targets_met", "secure"):
        assert k in res, k
    assert res["hosts"] == ["BN", "A", "B", "C"] and res["ea_peers"] == 15 and res["secure"] is True
    assert res["link_rate_kbps"] == 64
    assert res["peers_compared"] == 15 and res["alerts_compared"] > 0
    assert res["alerts_equal_in_process"] is True, res["unequal"]
    assert res["times_real_time"] > 1
    assert set(res["links"]) == {"A-BN", "B-BN", "C-BN"}
    assert all(v["up_bytes"] > 0 and v["down_bytes"] > 0 for v in res["links"].values())
    assert res["cut"] is None and res["host_kill"] is None
    assert not res["left_processes"]["free"] and not res["errors"]["free"]
