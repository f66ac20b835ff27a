"""The robot team on the live mesh (issue 50, the robot team on the same mesh): `mesh up
scenarios/uv-team` runs a source per robot (its own radio: its states, sightings and agent
messages) and an EA peer per unit, secure, no replay; every EA raises what an in-process EA
fed the same sources in (event time, source) order raises."""
from __future__ import annotations

import subprocess
import sys

import pytest

from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.live.depend import cp_shares

from .conftest import ROOT
from .test_live import in_process, load, plan_alerts

pytestmark = pytest.mark.timeout(300)
UV = ROOT / "scenarios" / "uv-team"


def test_mesh_up_runs_the_robot_team_live_and_its_alerts_are_the_in_process_runs(tmp_path):
    out = tmp_path / "mesh"
    r = subprocess.run([sys.executable, "-m", "saim_mesh", "mesh", "up", str(UV), "--speed", "max", "--out-dir",
                        str(out), "--restarts", "0"], capture_output=True, text=True, timeout=280)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "replay" not in r.stdout.lower()
    sc = S.load(UV)
    shares = cp_shares(sc)
    streams = {n: list(play.of_share(sc, sh)) for n, sh in shares.items()}
    robots = [u for u in sc.taskorg.units if u != sc.taskorg.root]
    assert all(streams[f"cp.{u}"] for u in robots)            # each robot's own radio carries its reports
    total = 0
    for u in sc.taskorg.units:
        want = plan_alerts(in_process(sc, u, streams))
        assert plan_alerts(load(out / f"{u}.jsonl")) == want, u
        total += len(want)
    assert total >= 20
