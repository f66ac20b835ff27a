"""Fusion near its sensors on the live mesh (issue 50): each sensor group's fusion node is
its own live source (`fusion.<G>`, its own identity), placed at the command post over the
group's sensors; the command posts' sources carry no raw hit; every EA raises what an
in-process EA fed the same sources in (event time, source) order raises."""
from __future__ import annotations

import subprocess
import sys

import pytest

from saim_mesh.protocol import messages as M
from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.live.depend import cp_shares, home_of

from .conftest import ROOT
from .test_live import in_process, load, plan_alerts

pytestmark = pytest.mark.timeout(400)
SENSORS = ROOT / "scenarios" / "small-sensors"
UNITS = ["BN", "A", "A2"]


@pytest.fixture(scope="module")
def sc():
    return S.load(SENSORS)


def test_each_sensor_group_is_a_source_of_tracks_and_no_raw_hit_leaves(sc):
    shares = cp_shares(sc)
    groups = sorted(sc.meta["fusion"]["groups"])
    assert [n for n, sh in shares.items() if sh.fusion] == [f"fusion.{g}" for g in groups]
    for n, sh in shares.items():
        kinds = {type(m) for m in play.of_share(sc, sh)}
        assert M.SensorHit not in kinds, n
        if sh.fusion:
            assert kinds == {M.SensorTrack}, n
    owners = {s["owner"] for s in sc.meta["fusion"]["sensors"] if s["group"] == groups[0]}
    home = home_of(sc, f"fusion.{groups[0]}")
    assert all(home == o or home in sc.taskorg.ancestors(o) for o in owners)   # over every sensor of the group


def test_a_fusion_node_of_an_unknown_group_is_refused_in_one_line():
    r = subprocess.run([sys.executable, "-m", "saim_mesh", "source", str(SENSORS), "--name", "fusion.Q", "--fusion",
                        "Q", "--connect", "tcp/127.0.0.1:9"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "unknown fusion group 'Q'" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_mesh_up_with_fusion_sources_gives_the_in_process_alerts(tmp_path, sc):
    out = tmp_path / "mesh"
    r = subprocess.run([sys.executable, "-m", "saim_mesh", "mesh", "up", str(SENSORS), "--units", *UNITS, "--speed",
                        "max", "--out-dir", str(out), "--restarts", "0"], capture_output=True, text=True, timeout=340)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "fusion.F" in r.stdout and "fusion.N" in r.stdout
    streams = {n: list(play.of_share(sc, sh)) for n, sh in cp_shares(sc).items()}
    for u in UNITS:
        want = plan_alerts(in_process(sc, u, streams))
        assert plan_alerts(load(out / f"{u}.jsonl")) == want, u
    assert any(a[1] in ("contact", "threat") for a in plan_alerts(load(out / "BN.jsonl")))
