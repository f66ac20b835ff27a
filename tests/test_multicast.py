"""`--multicast`: no endpoint to connect to; a live EA peer and its source find each other
by UDP multicast scouting and the peer raises what its plan implies (the in-process EA on
the same stream). Skipped where multicast scouting does not work on this host."""
from __future__ import annotations

import json
import threading
import uuid

import pytest

from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.launch.proc import Proc, clean_env, py

from .conftest import SMALL
from .test_live import in_process, load, plan_alerts

pytestmark = pytest.mark.timeout(300)


def _multicast_works() -> bool:
    """Probe: two sessions with multicast scouting and no endpoints find each other."""
    import zenoh

    from saim_mesh.launch.zenoh_config import config
    key, found = f"probe/{uuid.uuid4().hex}", threading.Event()
    with zenoh.open(config(["tcp/127.0.0.1:0"], [], multicast=True)) as a, \
            zenoh.open(config(["tcp/127.0.0.1:0"], [], multicast=True)) as b:
        sub = b.declare_subscriber(key, zenoh.handlers.FifoChannel(1))
        pub = a.declare_publisher(key)
        listener = pub.declare_matching_listener(lambda st: found.set() if st.matching else None)
        ok = pub.matching_status.matching or found.wait(10)
        del sub, listener
        return ok


def test_a_peer_and_its_source_find_each_other_by_multicast_scouting(tmp_path):
    if not _multicast_works():
        pytest.skip("UDP multicast scouting does not work on this host's network")
    sc = S.load(SMALL)
    zargs = ["--listen", "tcp/127.0.0.1:0", "--multicast", "--root", f"test/{uuid.uuid4().hex[:8]}"]
    procs = [Proc("peer-A2", [*py(), "peer", "--scenario", str(SMALL), "--unit", "A2", "--sources", "cp.all",
                              "--out", str(tmp_path / "A2.jsonl"), *zargs], env=clean_env(), log_dir=tmp_path)]
    try:
        procs[0].wait_for("ready A2", 60)
        procs.append(Proc("source-cp.all", [*py(), "source", str(SMALL), "--name", "cp.all", "--tracks", "--speed",
                                            "max", "--linger", "60", *zargs], env=clean_env(), log_dir=tmp_path))
        line = procs[0].wait_for("summary ", 240)
    finally:
        for p in procs:
            p.stop()
    assert all(p.p.poll() is not None for p in procs)
    assert json.loads(line.split(" ", 1)[1])["lost"] == {}
    want = plan_alerts(in_process(sc, "A2", {"cp.all": list(play.share(sc, None, True))}))
    assert len(want) >= 5 and plan_alerts(load(tmp_path / "A2.jsonl")) == want
