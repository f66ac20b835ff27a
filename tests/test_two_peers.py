"""Two EA peers of one unit on the live mesh (a spare beside the primary, loopback, free
ports, every child reaped): fed by the same source, each raises exactly what the
in-process EA on that stream raises, so either can stand in for the other."""
from __future__ import annotations

import uuid

import pytest

from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.proc import Proc, clean_env, py
from saim_mesh.zconf import free_port

from .conftest import SMALL
from .test_live import in_process, load, plan_alerts

pytestmark = pytest.mark.timeout(300)


def test_two_peers_for_one_unit_raise_identical_alerts(tmp_path):
    sc = S.load(SMALL)
    root = f"test/{uuid.uuid4().hex[:8]}"
    eps = [f"tcp/127.0.0.1:{free_port()}" for _ in range(2)]
    procs = [Proc(f"peer-A2-{i}", [*py(), "peer", "--scenario", str(SMALL), "--unit", "A2", "--sources", "cp.all",
                                   "--listen", ep, "--root", root, "--out", str(tmp_path / f"A2-{i}.jsonl")],
                  env=clean_env(), log_dir=tmp_path) for i, ep in enumerate(eps)]
    try:
        for p in procs:
            p.wait_for("ready A2", 60)
        procs.append(Proc("source-cp.all", [*py(), "source", str(SMALL), "--name", "cp.all", "--tracks", "--speed",
                                            "max", "--linger", "60", "--connect", *eps, "--root", root],
                          env=clean_env(), log_dir=tmp_path))
        for p in procs[:2]:
            p.wait_for("summary ", 240)
    finally:
        for p in procs:
            p.stop()
    assert all(p.p.poll() is not None for p in procs)
    want = plan_alerts(in_process(sc, "A2", {"cp.all": list(play.share(sc, None, True))}))
    got = [plan_alerts(load(tmp_path / f"A2-{i}.jsonl")) for i in range(2)]
    assert len(want) >= 5 and got[0] == got[1] == want
