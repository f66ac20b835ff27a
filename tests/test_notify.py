"""A commander's actions on an EA, in process on the small scenario (docs/console.md 1):
alert ids, repeats and escalation of unacknowledged urgent alerts, silences, thresholds
changed at run time, and bad input refused with nothing changed."""
from __future__ import annotations

import copy
import logging

import pytest

from ea_agent.core.config import ConfigError
from saim_mesh import commands as C
from saim_mesh import messages as M
from saim_mesh.runner import config_for, make_ea

OWNER = "A2"


def run_a2(small, actions=(), armed=True, until=None):
    """A2's EA over the small scenario; `actions` are (t, fn(ea)) done when scenario time
    reaches t (before the first event at or after t). Projections are off: these tests
    follow A2's out-of-position alerts as the paper's EA raises them (the projection of
    the same story is tested in test_alert_types)."""
    cfg = config_for(small, OWNER)
    cfg["voi"]["projection_horizon_s"] = 0.0
    ea = make_ea(small, OWNER, cfg)
    C.tap(ea)
    if armed:
        ea.arm()
    ea.start(0.0)
    todo = sorted(actions, key=lambda x: x[0])
    for ev in small.events:
        if until is not None and ev.t >= until:
            break
        while todo and ev.t >= todo[0][0]:
            t, fn = todo.pop(0)
            ea.advance(t)
            fn(ea)
        ea.submit(ev)
    for t, fn in todo:
        ea.advance(t)
        fn(ea)
    ea.finish(until if until is not None else small.duration_s)
    return ea


def of(ea, typ=None, **details):
    return [a for a in ea.alerts if (typ is None or a.type == typ)
            and all(a.details.get(k) == v for k, v in details.items())]


def test_ids_are_unique_and_deterministic(small):
    a, b = run_a2(small, armed=False), run_a2(small, armed=False)
    ids = [x.details["id"] for x in a.alerts]
    assert ids == [f"{OWNER}/{n}" for n in range(1, len(ids) + 1)]
    assert ids == [x.details["id"] for x in b.alerts]
    assert not of(a, repeats=1)   # not armed (no commander acted): the paper's baseline, no repeats


def test_unacknowledged_urgent_alert_repeats_and_escalates(small):
    ea = run_a2(small, until=1200.0)
    first = next(a for a in ea.alerts if a.priority == "immediate")
    assert (first.t, first.type, first.details["id"]) == (942.0, "out-of-position", "A2/1")
    reps = of(ea, repeat_of="A2/1")
    step, n = ea.notify.repeat_s, ea.notify.escalate_after
    assert [r.t for r in reps] == [first.t + step * k for k in range(1, len(reps) + 1)]
    assert len(reps) == int((1200.0 - first.t) // step)
    assert [r.details["repeats"] for r in reps] == list(range(1, len(reps) + 1))
    assert [r.priority for r in reps] == ["immediate"] * n + ["flash"] * (len(reps) - n)
    assert all((r.type, r.subjects, r.message) == (first.type, first.subjects, first.message) for r in reps)
    assert len({a.details["id"] for a in ea.alerts}) == len(ea.alerts)
    assert ea.stats["repeats"] == len(of(ea, None, repeat_of="A2/1")) + sum(
        1 for a in ea.alerts if a.details.get("repeat_of") not in (None, "A2/1"))
    # a flash alert stays flash
    ff = [a for a in ea.alerts if a.priority == "flash" and "repeat_of" not in a.details]
    assert ff and all(r.priority == "flash" for a in ff for r in of(ea, repeat_of=a.details["id"]))


def test_ack_stops_repeats(small):
    acks = []
    ea = run_a2(small, [(1070.0, lambda e: acks.append(e.ack("A2/1")))], until=1500.0)
    reps = of(ea, repeat_of="A2/1")
    assert [r.t for r in reps] == [1002.0, 1062.0]
    assert acks[0]["stopped"] and acks[0]["repeats"] == 2
    # acknowledging one of its repeats acknowledges the chain
    ea2 = run_a2(small, [(1010.0, lambda e: e.ack(of(e, repeat_of="A2/1")[0].details["id"]))], until=1500.0)
    assert [r.t for r in of(ea2, repeat_of="A2/1")] == [1002.0]
    ea2.ack("A2/1")   # again: fine, nothing to stop


def test_silence_marks_matching_alerts_and_expires(small):
    ea = run_a2(small, [(0.0, lambda e: e.silence("s1", types=["out-of-position"], until_t=1100.0,
                                                  comment="known"))])
    oop = of(ea, "out-of-position")
    assert [(a.t, a.details.get("silenced")) for a in oop if "repeat_of" not in a.details] == \
        [(942.0, "s1"), (1062.0, "s1"), (1216.0, None)]
    assert not of(ea, repeat_of=oop[0].details["id"])   # silenced: never repeated
    assert "s1" not in ea.notify.silences               # expired
    assert ea.stats["silenced"] == 2
    # subjects and areas must match too; unsilence lifts it at once
    ea2 = run_a2(small, [(0.0, lambda e: e.silence("s2", types=["out-of-position"], subjects=["nobody"],
                                                   until_t=5000.0))])
    assert not [a for a in ea2.alerts if "silenced" in a.details]
    ea3 = run_a2(small, [(0.0, lambda e: e.silence("s3", types=["out-of-position"], until_t=5000.0)),
                         (1000.0, lambda e: e.unsilence("s3"))])
    assert [a.details.get("silenced") for a in of(ea3, "out-of-position") if "repeat_of" not in a.details] == \
        ["s3", None, None]


def test_set_threshold_applies_from_the_next_epoch_and_is_logged(small, caplog):
    caplog.set_level(logging.INFO, logger="ea_agent.core.notify")
    base = run_a2(small, armed=False)
    assert len(of(base, "out-of-position")) == 3
    ea = run_a2(small, [(1000.0, lambda e: e.set_param("voi.out_of_position_m", 1e6))], armed=False)
    (ch,) = ea.changes
    assert ch["key"] == "voi.out_of_position_m" and ch["old"] == 150.0 and ch["new"] == 1e6
    assert ch["asked_t"] == 1000.0 and 1000.0 < ch["t"] <= 1000.0 + ea.epoch_s
    assert ea.cfg["voi"]["out_of_position_m"] == 1e6 and ea.stats["settings"] == 1
    assert [a.t for a in of(ea, "out-of-position")] == [942.0]   # before the change only
    assert "voi.out_of_position_m = 1000000.0 (was 150.0)" in caplog.text
    # a VOA value cached at init follows the change
    ea2 = run_a2(small, [(10.0, lambda e: e.set_param("voa.suppress_friendly_s", 5)),
                         (20.0, lambda e: e.set_param("voa.repeat.out-of-position", 1.0))], armed=False)
    assert ea2.voa.suppress_friendly == 5.0 and ea2.voa.repeat["out-of-position"] == 1.0
    assert [c["key"] for c in ea2.changes] == ["voa.suppress_friendly_s", "voa.repeat.out-of-position"]


def test_bad_input_raises_and_changes_nothing(small):
    ea = run_a2(small, until=1000.0)
    cfg, n_alerts, chains = copy.deepcopy(ea.cfg), len(ea.alerts), dict(ea.notify.chains)
    for bad in ("A2/999", "B/1", "A2/0", "A2/x", "", "A2/w1"):
        with pytest.raises(KeyError, match="unknown alert"):
            ea.ack(bad)
    for key, value, match in [
            ("voi.nope", 1.0, "unknown key"), ("manager.epoch_s", 1.0, "unknown key"),
            ("voa.repeat", 1.0, "is a table"), ("voi.out_of_position_m", "far", "expected a number"),
            ("voi.out_of_position_m", True, "expected a number"), ("voi.out_of_position_m", -5.0, "must be > 0"),
            ("voi.out_of_position_m", 0, "must be > 0"), ("voi.danger_close_m", -1, "must be >= 0"),
            ("voi.schedule_repeat_s", [30.0, "x"], "expected a number"),
            ("voi.schedule_repeat_s", [], "must not be empty"), ("voi.out_of_position_m", float("nan"), "finite")]:
        with pytest.raises(ConfigError, match=match):
            ea.set_param(key, value)
    with pytest.raises(ValueError, match="until_t"):
        ea.silence("s", types=["contact"], until_t=10.0)   # already past
    with pytest.raises(ValueError, match="at least one"):
        ea.silence("s", until_t=5000.0)
    with pytest.raises(ValueError, match="types"):
        ea.silence("s", types=[3], until_t=5000.0)
    with pytest.raises(KeyError, match="unknown silence"):
        ea.unsilence("nope")
    assert ea.cfg == cfg and not ea.notify.pending and not ea.changes and not ea.notify.silences
    assert len(ea.alerts) == n_alerts and dict(ea.notify.chains) == chains


def test_commands_apply_in_process(small):
    """`commands.apply`: the same effects as the EA's methods, answered, never raising."""
    ea = run_a2(small, armed=False, until=3950.0)
    ok = C.apply(ea, C.make("ack", alert="A2/1", by="cdr"))
    assert ok.ok and ok.kind == "ack" and ok.t == ea.now and ea.notify.armed
    bad = C.apply(ea, C.make("ack", alert="A2/999"))
    assert not bad.ok and "unknown alert" in bad.error and bad.req != ok.req
    res = C.apply(ea, C.make("set", key="voi.out_of_position_m", value=-1))
    assert not res.ok and "must be > 0" in res.error
    res = C.apply(ea, C.make("set", key="voi.out_of_position_m", value=300))
    assert res.ok and res.t == ea.epoch_end and ea.notify.pending
    assert not C.apply(ea, C.make("unsilence", id="zz")).ok
    assert C.apply(ea, C.make("silence", id="s", types=["contact"], until_t=5000.0)).ok
    assert C.apply(ea, C.make("unsilence", id="s")).ok
    # confirm: a local MissionConfirm at the EA's time; unknown mission refused
    mid = next(iter(ea.domain.missions))
    n_in = ea.n_in
    assert C.apply(ea, C.make("confirm", mission=mid, phase="start")).ok and ea.n_in == n_in + 1
    assert not C.apply(ea, C.make("confirm", mission="nope", phase="end")).ok
    # cff: confirm one the EA has seen; cancel forgets it
    seen = C.tap(ea)
    cff = next(iter(seen))
    assert isinstance(seen[cff], M.CallForFire)
    assert C.apply(ea, C.make("cff", cff=cff, action="confirm")).ok
    assert C.apply(ea, C.make("cff", cff=cff, action="cancel")).ok
    again = C.apply(ea, C.make("cff", cff=cff, action="confirm"))
    assert not again.ok and "unknown call for fire" in again.error
    with pytest.raises(ValueError, match="value"):
        C.make("set", key="voi.x", value="far")
    with pytest.raises(ValueError, match="phase"):
        C.make("confirm", mission="m", phase="later")
    with pytest.raises(ValueError, match="unknown command kind"):
        C.make("reboot")
