"""Robots obey their EAs over the mesh (issue 33.5): one process per robot and one per EA on
loopback behind a router. The closed loop gives the same reports, truth and alerts as in
process; a robot whose EA's commands are lost (an EA that publishes no task) and that
receives orders signed by someone else (a teammate's EA) refuses them and never pursues.
Every child is stopped by the driver, also on failure; nothing waits on the wall clock."""
from __future__ import annotations

import json

import pytest

from saim_mesh import scenario as S
from saim_mesh.robots.team import run_team
from saim_mesh.inprocess.runner import run

from .conftest import ROOT

UV = ROOT / "scenarios" / "uv-team"
pytestmark = pytest.mark.timeout(400)


def test_the_team_on_the_mesh_equals_the_closed_loop_in_process(tmp_path):
    res = run_team(tmp_path, timeout=300, echo=lambda *a, **k: None)
    assert res["secure"] and res["robot_processes"] == 5 and res["ea_processes"] == 6
    assert all(s["steps"] == 1801 and s["refused"] == 0 for s in res["robots"].values()), res["robots"]
    # the robots' reports and the truth of their run: exactly scenarios/uv-team (made in process)
    assert (tmp_path / "events.jsonl.gz").read_bytes() == (UV / "events.jsonl.gz").read_bytes()
    assert (tmp_path / "truth.json").read_bytes() == (UV / "truth.json").read_bytes()
    sc = S.load(UV)
    in_process = run(sc, sc.truth()["owners"])
    want = {ea.owner: [json.loads(json.dumps(a.to_json_dict())) for a in ea.alerts] for ea in in_process}
    assert res["alerts"] == want
    # each robot's EA hears only the teammates within its comm range: on the mesh it leaves out
    # exactly the states the in-process EA leaves out; the operator's (TEAM) hears every robot
    out_of_range = {ea.owner: ea.domain.watchman.dropped for ea in in_process}
    assert {u: s["out_of_range"] for u, s in res["eas"].items()} == out_of_range
    assert out_of_range[sc.taskorg.root] == 0 and sum(out_of_range.values()) > 0, out_of_range
    assert sum(s["commits"] for s in res["robots"].values()) >= 5   # the EAs' pursuits were carried out
    assert sum(s["tasks"] for s in res["eas"].values()) == sum(s["tasks_taken"] for s in res["robots"].values())


def test_a_robot_without_its_eas_commands_does_not_pursue(tmp_path):
    """UGV1's EA publishes no task, and every task it decided is published signed by
    UGV2's EA instead (plain TCP, no access control): UGV1 refuses those on their
    signature, sees EV1 (from about 372 s), never pursues."""
    res = run_team(tmp_path, until=420.0, mute=("UGV1",), forge={"UGV1": "ea.UGV2"}, timeout=300,
                   echo=lambda *a, **k: None, secure=False)
    ugv1 = res["robots"]["UGV1"]
    assert res["eas"]["UGV1"]["tasks"] >= 1 and res["eas"]["UGV1"]["published"] == 0   # decided, not sent
    assert ugv1["refused"] >= 1 and ugv1["commits"] == 0 and ugv1["tasks_taken"] == 0
    rec = json.loads((tmp_path / "robots" / "UGV1.json").read_text())
    assert any("ea.UGV2 may not sign" in why for why in rec["refused"]), rec["refused"]
    assert any(e["kind"] == "uv-sighting" and e["target"] == "EV1" for e in rec["events"])   # it saw EV1
    assert not any(str(x).startswith("pursue:") for x in rec["task"])
    assert any(a["type"] == "target-visible" and "EV1" in a["subjects"] for a in res["alerts"]["UGV1"])


def test_orders_for_a_robot_from_another_identity_do_not_cross_the_access_control(tmp_path):
    """Secure mode: the same orders put by UGV2's EA over its own mTLS session on UGV1's
    task key are dropped by the access control (ea.UGV2 may put only on task/UGV2): UGV1
    never even sees them, and never pursues."""
    res = run_team(tmp_path, until=420.0, mute=("UGV1",), forge={"UGV1": "ea.UGV2"}, timeout=300,
                   echo=lambda *a, **k: None)
    assert res["secure"] and res["eas"]["UGV1"]["forged"] >= 1
    ugv1 = res["robots"]["UGV1"]
    assert ugv1["refused"] == 0 and ugv1["commits"] == 0 and ugv1["tasks_taken"] == 0
    assert any(a["type"] == "target-visible" and "EV1" in a["subjects"] for a in res["alerts"]["UGV1"])
    assert res["robots"]["UGV3"]["commits"] >= 1   # the others obey their EAs as usual
