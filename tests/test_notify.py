"""A commander's actions on an EA, in process on the small scenario (docs/console.md 1):
alert ids, repeats and escalation of unacknowledged urgent alerts, silences, thresholds
changed at run time, and bad input refused with nothing changed."""
from __future__ import annotations

import copy
import logging

import pytest

from ea_agent.core.config import ConfigError
from saim_mesh.authority import commands as C
from saim_mesh.protocol import messages as M
from saim_mesh.protocol import wire as W
from saim_mesh.inprocess.runner import config_for, make_ea

OWNER = "A2"


def run_a2(small, actions=(), armed=True, until=None, config=None):
    """A2's EA over the small scenario; `actions` are (t, fn(ea)) done when scenario time
    reaches t (before the first event at or after t). Projections are off: these tests
    follow A2's out-of-position alerts as the paper's EA raises them, those of its move (its seize
    not on OBJ-A by its time at 3300 is another story; the projection of
    the same story is tested in test_alert_types). The notice budget is off: these tests
    follow the cadence itself (the budget is tested in test_commander_bound)."""
    cfg = config_for(small, OWNER)
    cfg["voi"]["projection_horizon_s"] = 0.0
    cfg["notify"]["budget"] = 0.0
    if config is not None:
        config(cfg)
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


def notices(ea, kind=None, alert=None):
    return [n for n in ea.notices if (kind is None or n.kind == kind) and (alert is None or n.alert == alert)]


def aid(ea, n: int) -> str:
    """The id of the EA's n-th alert (ids name what an alert says, not its rank)."""
    return ea.alerts[n - 1].details["id"]


def test_ids_are_unique_and_deterministic(small):
    a, b = run_a2(small, armed=False), run_a2(small, armed=False)
    ids = [x.details["id"] for x in a.alerts]
    assert len(set(ids)) == len(ids) and all(i.startswith(f"{OWNER}/{int(x.t)}.") for i, x in zip(ids, a.alerts))
    assert ids == [x.details["id"] for x in b.alerts]
    assert not a.notices   # not armed (no commander acted): the paper's baseline, nobody to re-notify


def test_stories_fold_a_storys_updates(small):
    ea = run_a2(small, armed=False)
    oop = of(ea, "out-of-position", mission="A2-move")
    # the same unit out of position three times within the VOA expiry: one story
    assert len(oop) == 3 and [a.details["story"] for a in oop] == [oop[0].details["id"]] * len(oop)
    others = [a for a in ea.alerts if (a.type, a.subjects) != (oop[0].type, oop[0].subjects)]
    assert all(a.details["story"] != oop[0].details["id"] for a in others)
    # its seize not on the objective by its time, long after: another mission, its own story
    (late,) = of(ea, "out-of-position", mission="A2-attack")
    assert (late.t, late.details["check"]) == (3300.0, "by") and late.details["story"] == late.details["id"]


def test_unacknowledged_urgent_alert_is_renotified_never_reraised(small):
    """Re-notifications are notices, at `[notify.immediate]` cadence and cap; the alerts
    (times, types, priorities, messages) are exactly the unarmed run's."""
    armed, plain = run_a2(small), run_a2(small, armed=False)
    key = lambda a: (a.t, a.type, a.priority, a.subjects, a.message, a.details["id"])   # noqa: E731
    assert [key(a) for a in armed.alerts] == [key(a) for a in plain.alerts]
    first = next(a for a in armed.alerts if a.priority == "immediate")
    assert (first.t, first.type, first.details["id"]) == (942.0, "out-of-position", aid(armed, 1))
    every, times = armed.cfg["notify"]["immediate"]["every_s"], armed.cfg["notify"]["immediate"]["times"]
    ren = notices(armed, "renotify", aid(armed, 1))
    assert [(n.t, n.count) for n in ren] == [(first.t + every * k, k) for k in range(1, times + 1)]
    assert all((n.type, n.priority, n.subjects, n.message, n.to, n.due_t) ==
               (first.type, first.priority, first.subjects, first.message, OWNER, first.t) for n in ren)
    (esc,) = notices(armed, "escalate", aid(armed, 1))
    assert esc.t == first.t + armed.cfg["notify"]["escalate_s"] and esc.to == "A" and esc.priority == "immediate"
    assert armed.stats["renotifications"] == len(notices(armed, "renotify"))
    assert armed.stats["escalations"] == len(notices(armed, "escalate"))
    # flash alerts are re-notified at their own cadence, and stay flash
    for a in (x for x in armed.alerts if x.priority == "flash"):
        fl = notices(armed, "renotify", a.details["id"])
        assert [n.t - a.t for n in fl] == [armed.cfg["notify"]["flash"]["every_s"] * k
                                          for k in range(1, len(fl) + 1)]
        assert len(fl) <= armed.cfg["notify"]["flash"]["times"] and all(n.priority == "flash" for n in fl)


def test_cadence_cap_and_escalation_are_configuration(small):
    def cadence(cfg):
        cfg["notify"]["immediate"] = {"every_s": 60.0, "times": 5}
        cfg["notify"]["escalate_s"] = 0.0
    ea = run_a2(small, config=cadence)
    assert [n.t for n in notices(ea, "renotify", aid(ea, 1))] == [942.0 + 60.0 * k for k in range(1, 6)]
    assert not notices(ea, "escalate")


def test_ack_stops_renotification_and_escalation(small):
    acks = []
    ea = run_a2(small, [(1300.0, lambda e: acks.append(e.ack(aid(e, 1))))], until=2500.0)
    # at 1242 (300 s after it): re-notified once and escalated; acknowledged at 1300, the second
    # re-notification (1542) never comes
    assert [n.t for n in notices(ea, "renotify", aid(ea, 1))] == [1242.0]
    assert [n.t for n in notices(ea, "escalate", aid(ea, 1))] == [1242.0]
    assert acks[0]["stopped"] and acks[0]["renotified"] == 1 and acks[0]["escalated"]
    early = run_a2(small, [(1000.0, lambda e: e.ack(aid(e, 1)))], until=2500.0)
    assert not notices(early, alert=aid(early, 1))
    ea.ack(aid(ea, 1))   # again: fine, nothing to stop
    with pytest.raises(KeyError, match="unknown alert"):
        ea.ack("A2/999")


def test_a_modelled_commander_acknowledges_after_a_delay(small):
    """evaluate --commander: `arm(ack_after_s)` acknowledges each urgent alert that long after it."""
    diligent = run_a2(small, [(0.0, lambda e: e.arm(30.0))], armed=False)
    assert not diligent.notices and diligent.notify.acked and not diligent.notify.chains
    slow = run_a2(small, [(0.0, lambda e: e.arm(300.0))], armed=False)
    # immediate: nothing before 300 s; flash: re-notified at 120 and 240 s, then acknowledged
    assert all(n.kind == "renotify" and n.priority == "flash" for n in slow.notices)


def test_escalation_reaches_the_superiors_ea_in_process(small):
    from saim_mesh.inprocess.runner import run
    got = []
    eas = run(small, ["A", "A2"], armed=True, notice_sinks=[got.append])
    a, a2 = eas
    esc = notices(a2, "escalate")
    assert esc and all(n.to == "A" for n in esc)
    assert a.received == esc and a.stats["escalations_in"] == len(esc)
    assert [n for n in got if n.kind == "escalate" and n.owner == "A2"] == esc


def test_silence_marks_matching_alerts_and_expires(small):
    ea = run_a2(small, [(0.0, lambda e: e.silence("s1", types=["out-of-position"], until_t=1100.0,
                                                  comment="known"))])
    oop = of(ea, "out-of-position", mission="A2-move")
    assert [(a.t, a.details.get("silenced")) for a in oop] == [(942.0, "s1"), (1062.0, "s1"), (1216.0, None)]
    assert not notices(ea, alert=oop[0].details["id"])   # silenced: never re-notified or escalated
    assert [n.alert for n in notices(ea, "renotify")][:2] == [aid(ea, 3), aid(ea, 3)]   # a flash fratricide: not silenced
    assert "s1" not in ea.notify.silences               # expired
    assert ea.stats["silenced"] == 2
    # subjects and areas must match too; unsilence lifts it at once
    ea2 = run_a2(small, [(0.0, lambda e: e.silence("s2", types=["out-of-position"], subjects=["nobody"],
                                                   until_t=5000.0))])
    assert not [a for a in ea2.alerts if "silenced" in a.details]
    ea3 = run_a2(small, [(0.0, lambda e: e.silence("s3", types=["out-of-position"], until_t=5000.0)),
                         (1000.0, lambda e: e.unsilence("s3"))])
    assert [a.details.get("silenced") for a in of(ea3, "out-of-position", mission="A2-move")] == ["s3", None, None]


def test_a_silence_set_after_an_alert_stops_its_renotifications(small):
    """Silenced while it waits: nothing more of it, even after the silence ends (the
    commander knows of it); it can still be acknowledged."""
    ea = run_a2(small, [(1000.0, lambda e: e.silence("s", types=["out-of-position"], until_t=3000.0))])
    assert not notices(ea, alert=aid(ea, 1))
    assert ea.ack(aid(ea, 1))["stopped"]


RULE = {"id": "oop-after-oop", "source": {"types": ["out-of-position"]}, "target": {"types": ["out-of-position"]},
        "equal": ["subjects"], "for_s": 150.0}


def test_an_inhibition_rule_from_the_config_marks_and_quiets(small):
    ea = run_a2(small, config=lambda cfg: cfg.update(inhibit=[RULE]))
    oop = of(ea, "out-of-position", mission="A2-move")
    # 942 is the first (nothing active); 1062 falls within 150 s of it: inhibited by it; 1216 is 154 s after 1062
    assert [a.details.get("inhibited_by") for a in oop] == [None, {"rule": "oop-after-oop", "source": oop[0].details["id"]}, None]
    assert ea.stats["inhibited"] == 1 and not notices(ea, alert=oop[1].details["id"])
    assert notices(ea, alert=oop[0].details["id"])


def test_an_inhibition_rule_at_run_time_and_lifted(small):
    cmd = C.make("inhibit", id="r", source=W.MatcherSpec(types=["out-of-position"]),
                 target=W.MatcherSpec(types=["out-of-position"]), equal=["subjects"], for_s=150.0)
    ea = run_a2(small, [(0.0, lambda e: C.apply(e, cmd))])
    assert [bool(a.details.get("inhibited_by")) for a in of(ea, "out-of-position", mission="A2-move")] == [False, True, False]
    ea2 = run_a2(small, [(0.0, lambda e: C.apply(e, cmd)),
                         (1000.0, lambda e: C.apply(e, C.make("uninhibit", id="r")))])
    assert not [a for a in ea2.alerts if "inhibited_by" in a.details]
    bad = C.apply(ea2, C.make("uninhibit", id="r"))
    assert not bad.ok and "unknown rule" in bad.error


@pytest.mark.parametrize("rule,text", [
    ({"id": "x", "source": {"types": ["contact"]}}, "needs both 'source' and 'target'"),
    ({"id": "x", "source": {}, "target": {"types": ["a"]}}, "an empty matcher matches every alert"),
    ({"id": "x", "source": {"type": ["contact"]}, "target": {"types": ["a"]}}, "field 'type': unknown key"),
    ({"id": "x", "source": {"types": ["c"]}, "target": {"types": ["a"]}, "equal": ["unit"]}, "unknown label 'unit'"),
    ({"id": "x", "source": {"types": ["c"]}, "target": {"types": ["a"]}, "for_s": -1}, "field 'for_s'"),
    ({"id": "x", "source": {"types": ["c"]}, "target": {"priorities": ["urgent"]}}, "'urgent' is not one of"),
    ({"source": {"types": ["c"]}, "target": {"types": ["a"]}}, "field 'id'"),
    ({"id": "x", "source": {"types": ["c"]}, "target": {"types": ["a"]}, "when": 3}, "field 'when': unknown key"),
])
def test_a_bad_inhibition_rule_is_one_clear_line(small, tmp_path, rule, text):
    from ea_agent.core.config import load_config
    import tomllib  # noqa: F401 -- the file below is TOML
    ea = run_a2(small, armed=False, until=10.0)
    with pytest.raises(ValueError, match=text.replace("(", r"\(").replace(")", r"\)")):
        ea.inhibit(rule)
    # the same rule in a config file: a ConfigError naming the file
    p = tmp_path / "ea.toml"
    p.write_text("[[inhibit]]\n" + "\n".join(f"{k} = {_toml(v)}" for k, v in rule.items()) + "\n")
    with pytest.raises(ConfigError, match=r"ea\.toml: \[\[inhibit\]\]"):
        load_config(p)


def _toml(v):
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + " }"
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return f'"{v}"' if isinstance(v, str) else repr(v)


def test_unknown_notify_keys_are_refused(tmp_path):
    from ea_agent.core.config import load_config
    p = tmp_path / "ea.toml"
    p.write_text("[notify]\nrepeat_s = 60.0\n")
    with pytest.raises(ConfigError, match="field 'repeat_s': unknown key"):
        load_config(p)
    p.write_text("[notify.flash]\nevery = 60.0\n")
    with pytest.raises(ConfigError, match="field 'every': unknown key"):
        load_config(p)


def test_set_threshold_applies_from_the_next_epoch_and_is_logged(small, caplog):
    caplog.set_level(logging.INFO, logger="ea_agent.core.notify")
    base = run_a2(small, armed=False)
    assert len(of(base, "out-of-position", mission="A2-move")) == 3
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
    ok = C.apply(ea, C.make("ack", alert=aid(ea, 1), by="cdr"))
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


def test_an_inhibition_in_a_command_log_replays_with_run_armed_commands(small, tmp_path):
    """A rule set at run time is written to the EA's command log like any command, and
    `saim-mesh run --armed --commands` replays it: the same alerts, the same ones marked
    `inhibited_by`, as the EA that took it (none marked without the log)."""
    import json
    import subprocess
    import sys

    from saim_mesh.logs import cmdlog
    from saim_mesh.launch.proc import clean_env

    from .conftest import SMALL
    cmd = C.make("inhibit", id="r", source=W.MatcherSpec(types=["out-of-position"]),
                 target=W.MatcherSpec(types=["out-of-position"]), equal=["subjects"], for_s=150.0)
    ea = run_a2(small, [(0.0, lambda e: C.apply(e, cmd))], armed=False)   # only to get the EA's answer
    log = cmdlog.CommandLog(tmp_path / f"{OWNER}.cmdlog")
    log.write(OWNER, 0.0, cmd, C.apply(ea, cmd))
    log.close()

    def run(*extra) -> list[tuple]:
        out = tmp_path / f"run{len(extra)}.jsonl"
        subprocess.run([sys.executable, "-m", "saim_mesh", "run", str(SMALL), "--ea", OWNER, "--armed", "--quiet",
                        *extra, "--out", str(out)], check=True, env=clean_env(), stdout=subprocess.DEVNULL,
                       timeout=300)
        return [(a["t"], a["type"], tuple(a["subjects"]), a["message"], a["details"].get("inhibited_by"))
                for a in map(json.loads, open(out)) if a["category"] != "system-problem"]
    replayed, plain = run("--commands", str(tmp_path / f"{OWNER}.cmdlog")), run()
    marked = [a for a in replayed if a[4]]
    assert marked and all(a[1] == "out-of-position" and a[4]["rule"] == "r" for a in marked), marked
    assert not [a for a in plain if a[4]]
    assert [a[:4] for a in replayed] == [a[:4] for a in plain]   # inhibited: marked, never lost
