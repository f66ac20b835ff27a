"""A commander who never acknowledges is told a bounded amount more than the unwatched
run shows (issue 53.5): the notice budget (`ea_agent/core/budget.py`, `[notify] budget`)
holds re-notifications and escalations to a share of the commander's own new alerts, on
scenario time; a flash escalation still reaches the superior; budget = 0 is the old
cadence; a bad value is refused in one line."""
from __future__ import annotations

import subprocess
import sys

import pytest

from ea_agent.core.budget import Budget
from ea_agent.core.config import ConfigError, load_config
from saim_mesh import scenario as S
from saim_mesh.inprocess.evaluate import commander_view
from saim_mesh.inprocess.runner import config_for, run

from .conftest import BATTALION, ROOT, SMALL

OFF = {"notify": {"budget": 0.0}}


def test_the_budget_follows_event_time_and_what_the_commander_was_given():
    """Only the scenario times given count: a window of alerts earns budget x their number
    (at least the floor), the window slides, and the run's total stays within budget x its
    alerts; a forced notice (a flash escalation) is given and uses up budget."""
    b = Budget("A", {"budget": 0.5, "budget_min": 2.0, "budget_window_s": 100.0})
    for t in range(10):
        b.alert(float(t))
    assert [b.allow(10.0 + k) for k in range(7)] == [True] * 5 + [False] * 2
    assert b.allow(20.0, force=True) and b.forced == 1
    # an hour later the window is empty: the floor holds, but the run has spent what it earned
    assert not b.allow(500.0)
    for t in (600.0, 601.0, 602.0, 603.0):
        b.alert(t)
    assert [b.allow(610.0 + k) for k in range(3)] == [True, False, False]   # 0.5 x 14 = 7 in all
    assert b.stats() == {"given": 7, "dropped": 5, "forced": 1}
    quiet = Budget("A", {"budget": 0.5, "budget_min": 2.0, "budget_window_s": 100.0})
    assert [quiet.allow(1.0), quiet.allow(2.0), quiet.allow(3.0)] == [True, True, False]   # the floor
    off = Budget("A", {"budget": 0.0, "budget_min": 2.0, "budget_window_s": 100.0})
    assert all(off.allow(float(t)) for t in range(50)) and off.dropped == 0


@pytest.fixture(scope="module")
def company(small):
    """A and A2 armed over the small scenario, nobody acknowledging: (budget on, off, tight)."""
    def go(over):
        return {ea.owner: ea for ea in run(small, ["A", "A2"], armed=True, overrides=over)}
    tight = {"notify": {"budget": 0.01, "budget_min": 0.0}}   # nothing budgeted gets through
    return go(None), go(OFF), go(tight)


def shown_alerts(ea):
    return [a for a in ea.alerts if "silenced" not in a.details and "inhibited_by" not in a.details]


def told(eas, unit):
    """The notices shown to `unit`'s commander: its own re-notifications, escalations to it."""
    return sorted((n for ea in eas.values() for n in ea.notices if n.to == unit), key=lambda n: n.t)


def test_the_budget_bounds_what_a_commander_is_shown_in_a_run(company):
    on, off, _ = company
    for unit in ("A", "A2"):
        ea = on[unit]
        cfg = ea.cfg["notify"]
        alerts = [a.t for a in shown_alerts(ea)]
        notices = [n.t for n in told(on, unit)]
        assert len(notices) < len(told(off, unit))   # held back...
        assert len(notices) <= max(cfg["budget_min"], cfg["budget"] * len(alerts)) + ea.notify.budget.forced
        w = cfg["budget_window_s"]
        for t in notices:   # ... and in every window, on scenario time
            in_w = sum(1 for x in notices if t - w < x <= t)
            earned = sum(1 for x in alerts if t - w < x <= t)
            assert in_w <= max(cfg["budget_min"], cfg["budget"] * earned) + ea.notify.budget.forced
        assert ea.notify.budget.dropped > 0
    assert [a.details["id"] for a in shown_alerts(on["A2"])] == [a.details["id"] for a in shown_alerts(off["A2"])]


def test_budget_zero_is_the_old_cadence(company, small):
    """Off: every urgent alert left unacknowledged is re-notified `times` times (those the
    run's end cuts short excepted), and escalated once after escalate_s."""
    _, off, _ = company
    ea = off["A2"]
    n = ea.cfg["notify"]
    assert ea.notify.budget.dropped == 0
    for a in shown_alerts(ea):
        if a.priority not in ("flash", "immediate"):
            continue
        every, times = n[a.priority]["every_s"], n[a.priority]["times"]
        ren = [x.t for x in ea.notices if x.kind == "renotify" and x.alert == a.details["id"]]
        want = [a.t + every * k for k in range(1, times + 1) if a.t + every * k <= small.duration_s]
        assert ren == pytest.approx(want, abs=ea.epoch_s)
        esc = [x for x in ea.notices if x.kind == "escalate" and x.alert == a.details["id"]]
        assert len(esc) == (a.t + n["escalate_s"] <= small.duration_s - ea.epoch_s) and all(x.to == "A" for x in esc)


def test_an_unacknowledged_flash_still_reaches_the_superior(company, small):
    """With no budget to spare, A2's flash alerts are still escalated to A (and reach A's
    EA), and each flash alert is reminded once; its immediate ones and every other
    re-notification are held back."""
    _, off, tight = company
    a2, a = tight["A2"], tight["A"]
    esc_s = a2.cfg["notify"]["escalate_s"]
    flash = [x.details["id"] for x in shown_alerts(a2)
             if x.priority == "flash" and x.t + esc_s <= small.duration_s - a2.epoch_s]
    assert flash, "the small scenario gives A2 flash alerts"
    up = [x for x in a2.notices if x.kind == "escalate"]
    assert sorted(x.alert for x in up) == sorted(flash) and all(x.to == "A" and x.priority == "flash" for x in up)
    assert {x.alert for x in a.received} >= set(flash)   # A's EA took them
    assert a.notify.budget.forced >= len(flash)
    ren = [x for x in a2.notices if x.kind == "renotify"]
    # only a flash alert's first reminder gets past an empty budget: a threat to life is never said once
    assert ren and all(x.priority == "flash" and x.count == 1 for x in ren)
    assert sorted(x.alert for x in ren) == sorted({x.details["id"] for x in shown_alerts(a2) if x.priority == "flash"
                                                   and x.t + a2.cfg["notify"]["flash"]["every_s"] <= small.duration_s})
    assert any(x.kind == "escalate" and x.priority == "immediate" for x in off["A2"].notices)   # held back here


@pytest.mark.parametrize("over, says", [
    ({"budget": -0.5}, "[notify]: field 'budget': must be >= 0 (got -0.5)"),
    ({"budget": "half"}, "[notify]: field 'budget': expected a number, got a string ('half')"),
    ({"budget_window_s": 0.0}, "[notify]: field 'budget_window_s': must be > 0 (got 0.0)"),
    ({"budget_min": True}, "[notify]: field 'budget_min': expected a number, got a boolean (True)"),
    ({"budgets": 1.0}, "[notify]: field 'budgets': unknown key (known: budget, budget_min, budget_window_s,"),
])
def test_a_bad_budget_is_refused_in_one_line(over, says):
    with pytest.raises(ConfigError) as e:
        load_config(overrides={"notify": over})
    assert says in str(e.value) and "\n" not in str(e.value)


def test_a_bad_budget_file_is_refused_by_the_command_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[notify]\nbudget_window_s = -600\n")
    out = subprocess.run([sys.executable, "-m", "saim_mesh", "evaluate", str(SMALL), "--config", str(bad)],
                         capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode != 0 and out.stdout == ""
    assert out.stderr.strip().splitlines() == [f"saim-mesh: {bad}: [notify]: field 'budget_window_s': must be > 0 (got -600)"]


def test_the_uv_defaults_have_a_budget_of_their_own():
    from ea_agent import domains
    cfg = load_config(defaults=domains.get("uv").CONFIG_PATH)
    assert cfg["notify"]["budget_window_s"] < load_config()["notify"]["budget_window_s"]


@pytest.mark.parametrize("path", [SMALL, BATTALION], ids=["small", "battalion"])
def test_nobody_acknowledging_is_shown_at_most_half_again_the_unwatched_run(path):
    """evaluate --commander none: per commander, what they are shown (alerts, re-notifications,
    escalations) per hour is at most 1.5x the alerts the unwatched run shows them; recall,
    priorities and unwanted shares are the alerts' own."""
    sc = S.load(path)
    truth = sc.truth()
    owners = truth["owners"]
    plain = run(sc, owners)
    v = commander_view(sc, owners, "none", plain, truth)
    shown, unwatched = v["shown_per_commander_hour"], v["unwatched_per_commander_hour"]
    assert set(shown) == set(unwatched) == set(owners)
    for o in owners:
        assert unwatched[o] > 0 and shown[o] <= 1.5 * unwatched[o], (o, shown[o], unwatched[o])
        assert v["shown_over_unwatched"][o] <= 1.5
    assert v["shown_over_unwatched_worst"] == max(v["shown_over_unwatched"].values()) <= 1.5
    assert v["notices_dropped"] > 0 and v["escalations"] > 0 and v["renotifications"] > 0
    assert v["priorities_equal"] and v["recall"] == 1.0 and v["unwanted_flash"] == 0
    assert v["alerts"] == sum(len(ea.alerts) for ea in plain)
    assert config_for(sc, owners[0])["notify"]["budget"] > 0   # the default config bounds it
