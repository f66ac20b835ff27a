"""One id per alert for ever (issue 49.1, 49.4): an EA rebuilt after a source's loss,
restarted from its input journal, or joining late never gives one id to two alerts, and
gives every alert of the fault-free run the id it has there; a commander's commands given
before a loss or a restart are taken again by the rebuilt EA at the same event time; a
late joiner marks the past it is told as late. No network: frames are fed to the peer as
its subscriber would (tests/test_live_rebuild.py)."""
from __future__ import annotations

import json

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from saim_mesh.authority import commands as C
from saim_mesh import scenario as S
from saim_mesh.protocol import wire as W
from saim_mesh.live import frames as F
from saim_mesh.live import play
from saim_mesh.live.peer import LivePeer
from saim_mesh.launch.zenoh_config import config

from .conftest import SMALL
from .test_live_rebuild import frames

ROOT = "t/ids"


@pytest.fixture(scope="module")
def sc():
    return S.load(SMALL)


@pytest.fixture(scope="module")
def merged(sc):
    a = frames("src.a", list(play.share(sc, ["A"], False)))
    b = frames("src.b", list(play.share(sc, None, True, ["A"])))
    return sorted([(t, 0, f) for t, f in a] + [(t, 1, f) for t, f in b], key=lambda x: x[:2])


def mk(sc, out=None, armed=False) -> LivePeer:
    return LivePeer(sc, "BN", config(["tcp/127.0.0.1:0"], None), ROOT, ["src.a", "src.b"],
                    str(out) if out else None, armed=armed)


def sig(d: dict) -> tuple:
    return (d["type"], tuple(sorted(d["subjects"])), d["priority"], d["message"], round(d["t"], 3))


def ack(p: LivePeer, alert: str) -> W.CmdResult:
    """A commander's ack as it comes off the wire to the peer."""
    results = []
    p.out.result = results.append
    p.command(p.ks.cmd("BN", "ack", "BN"), W.encode(C.make("ack", alert=alert, by="BN")))
    (res,) = results
    return res


def run(sc, merged, out, cut=None, heal=None, restart_at=None, acks=(), armed=False):
    """The battle to the peer, src.b cut off from event time `cut` to `heal` (its frames
    held back, it declared lost, its backlog delivered at the heal), the peer killed and
    restarted from its journal after `restart_at`, acks [(t, id)] sent once the EA is at t.
    Returns the last peer and every ack's result."""
    p = mk(sc, out, armed)
    held, lost, healed = [], False, False
    todo, done = sorted(acks), []
    for t, i, f in merged:
        if restart_at is not None and t > restart_at:
            p.out.close()
            p = mk(sc, out, armed)
            p.restart()
            restart_at = None
        if cut is not None and not lost and not healed and t > cut:
            p.lose("src.b", "test: link cut")
            lost = True
        if lost and t > heal:
            for g in held:
                p.take(g, "")
            held, lost, healed = [], False, True
        if lost and i == 1:
            held.append(f)
            continue
        p.take(f, "")
        while todo and todo[0][0] <= p.ea.now:
            done.append(ack(p, todo.pop(0)[1]))
    for g in held:
        p.take(g, "")
    p.ea.finish(p.end_t())
    p.out.close()
    return p, done


def logged(path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


@pytest.fixture(scope="module")
def fault_free(sc, merged, tmp_path_factory):
    out = tmp_path_factory.mktemp("ff") / "BN.jsonl"
    run(sc, merged, out)
    return logged(out)


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.floats(200.0, 2500.0), length=st.floats(60.0, 1500.0),
       restart=st.one_of(st.none(), st.floats(100.0, 4500.0)))
def test_no_id_names_two_alerts_and_the_fault_free_alerts_keep_theirs(sc, merged, fault_free, tmp_path_factory,
                                                                       cut, length, restart):
    out = tmp_path_factory.mktemp("faulted") / "BN.jsonl"
    run(sc, merged, out, cut=cut, heal=cut + length, restart_at=restart)
    got = logged(out)
    named: dict[str, set] = {}
    for d in got:
        named.setdefault(d["details"]["id"], set()).add(sig(d))
    assert not {i: s for i, s in named.items() if len(s) > 1}, "an id naming two alerts"
    have = {(d["details"]["id"], sig(d)) for d in got}
    want = [(d["details"]["id"], sig(d)) for d in fault_free if d["category"] != "system-problem"]
    assert len(want) >= 5
    missing = [w for w in want if w not in have]
    assert not missing, missing[:3]
    shown = [d["details"]["id"] for d in got if not d["details"].get("inhibited_by")]
    assert len(shown) == len(set(shown)), "an alert shown twice"


def first_urgent(sc, merged, tmp_path) -> dict:
    out = tmp_path / "probe" / "BN.jsonl"
    out.parent.mkdir()
    run(sc, merged, out, armed=True)
    return next(d for d in logged(out) if d["priority"] in ("flash", "immediate")
                and d["category"] != "system-problem" and d["t"] > 300.0)


@pytest.mark.parametrize("fault", ["rebuild", "restart", "restart-then-rebuild"])
def test_commands_before_a_loss_or_a_restart_are_taken_again_at_their_time(sc, merged, tmp_path, fault):
    x = first_urgent(sc, merged, tmp_path)
    xid, t_ack = x["details"]["id"], x["t"] + 450.0
    (tmp_path / "ref").mkdir()
    ref, (ref_res,) = run(sc, merged, tmp_path / "ref" / "BN.jsonl", acks=[(t_ack, xid)], armed=True)
    assert ref_res.ok, ref_res.error
    assert ref.ea.notify.acked[xid] == ref_res.t
    renotified = [n.t for n in ref.ea.notices if n.alert == xid]
    assert renotified and all(t <= ref_res.t for t in renotified)   # the ack stopped them

    kw = {"rebuild": dict(cut=x["t"] + 50.0, heal=t_ack + 600.0),
          "restart": dict(restart_at=t_ack + 300.0),
          "restart-then-rebuild": dict(cut=x["t"] + 50.0, heal=t_ack + 600.0, restart_at=t_ack + 100.0)}[fault]
    (tmp_path / "f").mkdir()
    p, (res,) = run(sc, merged, tmp_path / "f" / "BN.jsonl", acks=[(t_ack, xid)], armed=True, **kw)
    assert res.ok and res.t == ref_res.t
    assert p.rebuilds == (0 if fault == "restart" else 1)
    # the rebuilt (or restarted) EA took the ack at the same event time: the alert it raised
    # again under the same id is acknowledged, and re-notified exactly as in the fault-free run
    assert p.ea.notify.acked.get(xid) == ref_res.t
    assert xid not in p.ea.notify.chains
    assert [n.t for n in p.ea.notices if n.alert == xid] == renotified
    journal = (tmp_path / "f" / "BN.input").read_bytes()
    assert b"cmd" in journal


def decoded(merged, source: int, k: int):
    return F.decode([f for _, i, f in merged if i == source][k], 1 << 20)


def test_a_late_joiner_marks_what_it_is_told_of_the_past_late(sc, merged):
    join_wm = 1760.0
    k = int(join_wm / 2.0) - 1   # the frames (2 s each) the sources had published when it joined
    p = mk(sc)
    p.join()
    p.heard(decoded(merged, 0, k))   # the first frames it hears: the publishers' history
    p.heard(decoded(merged, 1, k))
    for _, _, f in merged:           # the rest of the past from the sources' journals, then live
        p.take(f, "")
    p.ea.finish(p.end_t())
    plan = [a for a in p.given if not a.details.get("wall_clock_driven")]
    past = [a for a in plan if a.t <= join_wm]
    after = [a for a in plan if a.t > join_wm]
    assert past and after
    assert all(a.details.get("late") and a.details["due_from"] == a.t for a in past)
    assert not [a for a in after if a.details.get("late")]
    assert p.summary()["late_alerts"] == len(past)


def test_a_peer_on_the_mesh_before_its_sources_began_marks_nothing_late(sc, merged):
    p = mk(sc)
    p.join()
    p.heard(decoded(merged, 0, 0))
    p.heard(decoded(merged, 1, 0))
    assert not p.catching_up
    for _, _, f in merged:
        p.take(f, "")
    p.ea.finish(p.end_t())
    assert p.given and not [a for a in p.given if a.details.get("late")]
