"""Robots obey their EAs (issue 33.5), in process: the simulator holds no copy of the
policy (a robot whose EA's tasks never reach it patrols on, never pursuing), the closed
loop is deterministic and is what scenarios/uv-team records (the EAs given the recorded
reports raise exactly the alerts they raised in the loop), and a task frame is taken only
when signed by the robot's own EA."""
from __future__ import annotations

import json

import pytest

from ea_agent.domains.uv import generator as G
from ea_agent.domains.uv import tasks as T
from ea_agent.domains.uv.loop import ClosedLoop
from saim_mesh import scenario as S
from saim_mesh.robots import wire
from saim_mesh.inprocess.runner import run

from .conftest import ROOT

UV = ROOT / "scenarios" / "uv-team"
pytestmark = pytest.mark.timeout(300)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("uvloop")
    G.write_static(out)
    return out


@pytest.fixture(scope="module")
def loop(folder):
    return G.simulate(folder)[0]


def commits(robot) -> list[dict]:
    return [e for e in robot.log if e["what"] == "commit"]


def test_the_closed_loop_is_what_the_scenario_records(loop, folder):
    """Same reports as scenarios/uv-team, byte for byte, and every EA's alerts in the loop
    equal those of the EAs given the recorded reports (the replay `evaluate` scores)."""
    assert G.events_bytes(loop.events) == (UV / "events.jsonl.gz").read_bytes()
    sc = S.load(UV)
    replay = {ea.owner: [a.to_json_dict() for a in ea.alerts] for ea in run(sc, sc.truth()["owners"])}
    looped = {ea.owner: [a.to_json_dict() for a in ea.alerts] for ea in loop.eas}
    assert replay == looped
    assert sum(map(len, looped.values())) > 40


def test_every_task_kind_is_decided_and_carried_out_at_its_time(loop):
    """Pursue, Drop, Resume, Handoff and Accept all happen; each is carried out by its robot
    at exactly its `at`, a step after the epoch it was decided in."""
    kinds = {type(x).__name__ for x in loop.tasks}
    assert kinds == {"Pursue", "Drop", "Resume", "Handoff", "Accept"}, kinds
    for rid, robot in loop.robots.items():
        taken = robot.taken
        mine = [x for x in loop.tasks if x.robot == rid]
        assert [(d["at"], d["n"]) for d in taken] == [(x.at, x.n) for x in mine], rid
        assert all(d["t"] == d["at"] for d in taken), rid
    # the handoff: the delegating robot's delegate, then the teammate's accept a step later
    h = next(x for x in loop.tasks if isinstance(x, T.Handoff))
    acc = next(x for x in loop.tasks if isinstance(x, T.Accept) and x.robot == h.to)
    assert acc.frm == h.robot and acc.target == h.target and acc.at == h.at + T.LAG_S


def test_every_task_is_due_after_the_promise_its_ea_gave_before_it(loop):
    """An EA advanced to t has promised no task due at or before t + LAG_S - DT (its last
    watermark): each task it publishes then is due exactly at t + LAG_S, the robot's next
    step, and only robots' own EAs publish."""
    assert loop.drained
    for t, owner, x in loop.drained:
        assert x.robot == owner and x.at == t + T.LAG_S, (t, owner, x)


def test_a_robot_whose_ea_commands_do_not_reach_it_does_not_pursue(folder, loop):
    """UGV1's EA decides to pursue EV1 (as in the full loop), but its tasks are dropped:
    UGV1 keeps patrolling and never pursues; in the full loop it does."""
    assert commits(loop.robots["UGV1"])
    from ea_agent.domains.uv import load, make_ea
    sc = load(folder, events=False)
    dropped = ClosedLoop(G.robots(), [make_ea(sc, o) for o in sc.meta["default_eas"]], unheard={"UGV1"}).run()
    ugv1 = dropped.robots["UGV1"]
    assert any(isinstance(x, T.Pursue) and x.robot == "UGV1" for x in dropped.tasks)   # decided ...
    assert not commits(ugv1) and not ugv1.taken                                       # ... never obeyed
    assert not any(str(x).startswith("pursue:") for x in ugv1.task)
    assert {t for t in ugv1.task if t} == {"U1-goto", "U1-patrol"}


def test_without_tasks_no_robot_pursues():
    """The simulator alone (no EA at all): patrollers patrol, nobody commits to a pursuit
    but the planned one (UAV2's A2-pursue, a step of its recipe)."""
    bots = G.robots()
    for i in range(len(next(iter(bots.values())).times)):
        for r in bots.values():
            r.step(i)
    got = {rid: [e["target"] for e in commits(r)] for rid, r in bots.items()}
    assert got == {"UGV1": [], "UGV2": [], "UGV3": [], "UAV1": [], "UAV2": ["EV2"]}


def _frame(robot: str = "UGV1", **kw) -> T.TaskFrame:
    task = T.Pursue(robot=robot, at=10.0, n=1, target="EV1", sector="SEC-W", mission="m1")
    return T.TaskFrame(v=1, robot=kw.pop("frame_robot", robot), epoch=1, seq=1, wm=10.0, tasks=[task], **kw)


def test_only_the_robots_own_ea_may_sign_its_tasks(tmp_path):
    robots = ["UGV1", "UGV2"]
    wire.make_identities(tmp_path, ["TEAM", *robots], extra=["console.TEAM"])
    ver = wire.verifier(tmp_path, "r", robots)
    key = wire.task_key("r", "UGV1")
    f = wire.open_frame(ver, key, wire.seal(wire.signer(tmp_path, "ea.UGV1"), key, _frame()), "UGV1")
    assert isinstance(f.tasks[0], T.Pursue)
    for who in ("ea.UGV2", "ea.TEAM", "console.TEAM"):   # a teammate's EA, the operator's, a console
        with pytest.raises(ValueError, match="may not sign"):
            wire.open_frame(ver, key, wire.seal(wire.signer(tmp_path, who), key, _frame()), "UGV1")
    with pytest.raises(ValueError, match="came on"):      # UGV2's tasks replayed onto UGV1's key
        k2 = wire.task_key("r", "UGV2")
        wire.open_frame(ver, key, wire.seal(wire.signer(tmp_path, "ea.UGV2"), k2, _frame("UGV2")), "UGV1")
    with pytest.raises(ValueError):                        # unsigned
        wire.open_frame(ver, key, T.encode(_frame()), "UGV1")


def test_a_bad_task_frame_is_refused_in_one_line(tmp_path):
    with pytest.raises(T.TaskError, match="carries a task for"):
        T.decode(T.encode(_frame("UGV2", frame_robot="UGV1")))
    bad = json.loads(json.dumps({"v": 1, "robot": "UGV1", "epoch": 1, "seq": 1, "wm": 1.0,
                                 "tasks": [{"op": "self-destruct", "robot": "UGV1", "at": 1.0, "n": 1}]}))
    import msgspec
    with pytest.raises(T.TaskError, match="task frame"):
        T.decode(msgspec.msgpack.encode(bad))
    with pytest.raises(T.TaskError, match="over the"):
        T.decode(b"x" * 70_000)
