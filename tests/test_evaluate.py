"""The quality targets on ground truth (recall, unwanted share, flash, reduction vs naive)."""
import json
import subprocess
import sys

from saim_mesh import scenario as S
from saim_mesh.inprocess.evaluate import evaluate

from .conftest import BATTALION, ROOT, SMALL


def check(res):
    assert res["recall"] == 1.0, res["missed"]
    assert res["unwanted_share"] <= 0.05, res["unwanted_alerts"]
    assert res["unwanted_flash"] == 0
    assert res["naive_alerts"] >= 50 * res["alerts"]
    # the measure can fail: with VOA off, most alerts repeat what was told with no material change
    assert res["naive"]["unwanted_share"] >= 0.5 and res["naive"]["unwanted_flash"] > 0, res["naive"]
    check_projections(res)


def check_projections(res):
    """Issue 34: projections lead or are not projections (the oracle times the violation)."""
    p = res["projections"]
    assert p["alerts"] > 0 and p["after_the_fact"] == 0 and p["lead_s_median"] >= 30, p


def test_small_scenario_meets_targets():
    check(evaluate(S.load(SMALL)))


def test_battalion_meets_targets_via_cli():
    out = subprocess.run([sys.executable, "-m", "saim_mesh", "evaluate", str(BATTALION), "--json"],
                         capture_output=True, text=True, cwd=ROOT, timeout=600, check=True)
    res = json.loads(out.stdout)
    for k in ("recall", "unwanted_share", "unwanted_flash", "alerts", "naive_alerts"):
        assert k in res
    check(res)


UV_TEAM = ROOT / "scenarios" / "uv-team"


def test_robot_team_meets_targets_against_the_simulators_truth():
    """Every incident the independent oracle names is alerted to its owner in time,
    with no unwanted flash alert and far fewer alerts than the naive detector."""
    res = evaluate(S.load(UV_TEAM))
    assert res["incidents"] >= 30
    assert res["recall"] == 1.0, res["missed"]
    assert res["unwanted_share"] <= 0.05, res["unwanted_alerts"]
    assert res["unwanted_flash"] == 0
    assert res["naive_alerts"] >= 10 * res["alerts"]
    assert res["naive"]["unwanted_share"] >= 0.5, res["naive"]
    want = {"at-goal", "stuck", "divergent", "no-status", "target-visible", "lost-target", "target-gone",
            "collision", "handoff"}
    assert want <= set(res["by_type"]), res["by_type"]   # every paper alert type happens in the scenario


def test_a_projection_is_scored_by_lead_time_or_as_false():
    from ea_agent.core.alert import Alert
    from saim_mesh.inprocess.evaluate import score
    inc = {"owner": "A", "type": "out-of-position", "accept": ["out-of-position"], "subjects": ["A2"],
           "t0": 1000.0, "t1": 1100.0, "label": "A2 off route"}
    truth = {"incidents": [inc], "situations": []}
    early = Alert(700.0, "A", "projected-out-of-position", "constraint-violation-projected", "priority", ("A2",),
                  "A2 will leave its route", {"projects": "out-of-position"})
    r = score([early], truth)
    assert r["recall"] == 1.0 and r["projections"] == {"alerts": 1, "false": 0, "after_the_fact": 0, "lead_s": [300.0],
                                                   "lead_s_median": 300.0}
    too_early = Alert(300.0, "A", "projected-out-of-position", "constraint-violation-projected", "priority", ("A2",),
                      "A2 will leave its route", {"projects": "out-of-position"})
    r = score([too_early], truth)   # 700 s ahead: foretold nothing that came within the window
    assert r["recall"] == 0.0 and r["projections"]["false"] == 1 and r["unwanted"] == 1
    wrong = Alert(900.0, "A", "projected-late", "constraint-violation-projected", "priority", ("A2",), "late",
                  {"projects": "schedule"})
    assert score([wrong], truth)["projections"]["false"] == 1


def test_a_repeat_is_wanted_only_with_a_material_change():
    """The same story (owner, type, truth item, subjects): the first alert is news, a later one
    only when its severity moved by the fixed step (1.25x) the worse way; a count type at any rise."""
    from ea_agent.core.alert import Alert
    from saim_mesh.inprocess.evaluate import score
    inc = {"owner": "A", "type": "out-of-position", "accept": ["out-of-position"], "subjects": ["A2"],
           "t0": 0.0, "t1": 1000.0, "label": "A2 off"}
    oop = lambda t, d: Alert(t, "A", "out-of-position", "plan-constraint-violated", "immediate", ("A2",),  # noqa: E731
                             "off", {"distance_m": d})
    r = score([oop(10, 200), oop(20, 210), oop(30, 260), oop(40, 240), oop(50, 330)], {"incidents": [inc],
                                                                                     "situations": []})
    assert r["unwanted_repeats"] == 2 and r["unwanted"] == 2   # 210 and 240: no material change
    assert [a["details"]["distance_m"] for a in r["unwanted_alerts"]] == [210, 240]
    near = lambda t, d: Alert(t, "A", "fratricide", "friendly-activity", "flash", ("A2",), "near",  # noqa: E731
                              {"min_distance_m": d})
    inc2 = {**inc, "type": "fratricide", "accept": ["fratricide"], "life": True}
    r = score([near(10, 500), near(20, 450), near(30, 390)], {"incidents": [inc2], "situations": []})
    assert r["unwanted_repeats"] == 1 and r["unwanted_flash"] == 1   # 450 is not 1.25x closer than 500
    other = Alert(20, "A", "out-of-position", "plan-constraint-violated", "immediate", ("A3",), "off", {})
    assert score([oop(10, 200), other], {"incidents": [inc, {**inc, "subjects": ["A3"]}],
                                         "situations": []})["unwanted_repeats"] == 0   # another story


def test_a_commander_in_the_loop_sees_what_the_commander_model_implies(tmp_path):
    """evaluate --commander: the EAs armed; what each commander saw, scored. Nobody
    acknowledging is told more (re-notifications, escalations) than a diligent commander,
    who acknowledges before the first re-notification falls due; no alert changes priority.
    The notice budget is off: this follows the cadence (test_commander_bound the budget)."""
    from saim_mesh.inprocess.evaluate import commander_view
    from saim_mesh.inprocess.runner import run
    sc = S.load(SMALL)
    truth = sc.truth()
    owners = truth["owners"]
    off = tmp_path / "no-budget.toml"
    off.write_text("[notify]\nbudget = 0.0\n")
    plain = run(sc, owners, config_path=off)
    none = commander_view(sc, owners, "none", plain, truth, off)
    slow = commander_view(sc, owners, "slow", plain, truth, off)
    diligent = commander_view(sc, owners, "diligent", plain, truth, off)
    n_plain = sum(len(ea.alerts) for ea in plain)
    for v in (none, slow, diligent):
        assert v["priorities_equal"] and v["alerts"] == n_plain   # notices, never new alerts
        assert v["unwanted_share"] <= 0.05 and v["unwanted_flash"] == 0 and v["recall"] == 1.0
    assert none["renotifications"] > slow["renotifications"] > diligent["renotifications"] == 0
    assert none["escalations"] > 0 and slow["escalations"] <= none["escalations"] and diligent["escalations"] == 0
    assert none["shown"] == none["alerts_shown"] + none["renotifications"] + none["escalations"]
    assert none["shown_per_commander_hour_worst"] > diligent["shown_per_commander_hour_worst"]


def test_evaluate_commander_on_the_command_line():
    out = subprocess.run([sys.executable, "-m", "saim_mesh", "evaluate", str(SMALL), "--commander", "slow"],
                         capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "commander slow: shown" in out.stdout and "priorities as unarmed: True" in out.stdout
    bad = subprocess.run([sys.executable, "-m", "saim_mesh", "evaluate", str(SMALL), "--commander", "lazy"],
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert bad.returncode == 2 and "invalid choice: 'lazy'" in bad.stderr
