"""Projections lead or are not projections (issue 34, item 1): a projected violation is
raised only when the model puts it at least `[voi] projection_min_lead_s` ahead; a route
departure is projected from the unit's cross-track trend once every member's reports show
it (and the reports themselves confirm it); `evaluate` counts the projections raised at
or after the violation they foretell.

One small synthetic scenario per case (tests/synthetic.py): A1 marches east along RTE-1
(y = 0) at 4 m/s from its start at t=100 and drifts north (or south) of it as a test says;
out_of_position_m is 150 m. Geometry in local metres east/north."""
from __future__ import annotations

import pytest

from ea_agent.core.config import ConfigError, load_config
from ea_agent.core.alert import Alert
from ea_agent.domains.suo.detect import projection as P
from ea_agent.domains.suo.messages import LocationReport
from saim_mesh.inprocess.evaluate import score
from benchmarks.evaluate_seeds import summarize
from saim_mesh.inprocess.runner import config_for

from .synthetic import Force, alerts_of, box, line, ll, mission, play, start, track_path

THR = 150.0
RTE_1 = line("RTE-1", "route", (-500, 0), (8500, 0))
AA_E = box("AA-E", "assembly-area", 7800, -300, 8200, 300)
BP_HOME = box("BP-HOME", "battle-position", -200, -200, 200, 200)
FEATURES = [RTE_1, AA_E, BP_HOME]
FORCE = Force(name="projection-lead")


def march(tmp_path):
    return FORCE.scenario(tmp_path, FEATURES, [mission("A1-move", "A1", "move", route="RTE-1", destination="AA-E")])


def drift(v: float, t0: float = 400.0, until: float = 1e9, back: float | None = None):
    """East at 4 m/s from t=100; from t0 `v` m/s across the route (north when > 0) until
    `until`, then (with `back`) back at `back` m/s to the route and along it again."""
    def where(t):
        x = 4.0 * max(0.0, t - 100.0)
        out = v * (min(t, until) - t0) if t > t0 else 0.0
        if back is not None and t > until:
            out = max(0.0, abs(out) - back * (t - until)) * (1 if v > 0 else -1)
        return x, out
    return where


def run(tmp_path, where, t1: float, cfg_overrides: dict | None = None):
    sc = march(tmp_path)
    msgs = FORCE.path("A1", 10, t1, where) + FORCE.stays("A2", 0, -3000, 10, t1) + [start(100, "A1-move", "A1")]
    cfg = config_for(sc, "A", overrides=cfg_overrides) if cfg_overrides else None
    return play(sc, msgs, t1, cfg=cfg)


def of(ea, typ):
    return alerts_of(ea, typ, "A1-move")


def table(*rows) -> str:
    return "\n".join(f"{(a.t, a.type, a.details.get('lead_s'), a.details.get('distance_m'))}" for a in rows)


# ------------------------------------------------------------------------ the configuration key
def test_the_minimum_lead_is_a_voi_key_of_the_suo_configuration():
    cfg = load_config()
    assert cfg["voi"]["projection_min_lead_s"] == 30.0
    assert load_config(overrides={"voi": {"projection_min_lead_s": 0}})["voi"]["projection_min_lead_s"] == 0.0
    with pytest.raises(ConfigError, match="field 'projection_min_lead_s': must be >= 0"):
        load_config(overrides={"voi": {"projection_min_lead_s": -1}})
    with pytest.raises(ConfigError, match="field 'projection_min_lead_s': expected a number"):
        load_config(overrides={"voi": {"projection_min_lead_s": "30"}})


# ------------------------------------------------------------------------ route departures
def test_a_departure_too_fast_to_foretell_is_not_projected_after_the_fact(tmp_path):
    """6 m/s across the route from t=400: 150 m off at t=425, before a trend could put it
    30 s ahead. No projection (it would come after or just before the fact); the actual
    alert tells it as soon as the reports show it out."""
    ea = run(tmp_path, drift(6.0), 700)
    assert not of(ea, "projected-out-of-position"), table(*of(ea, "projected-out-of-position"))
    oop = of(ea, "out-of-position")
    assert oop and 425 <= oop[0].t <= 440 and oop[0].priority == "immediate", table(*oop)


def test_with_no_minimum_lead_the_same_departure_would_be_projected_too_late_to_matter(tmp_path):
    """The twin of the test above with projection_min_lead_s = 0: the model does foretell
    the crossing, but less than a report interval before it (what the key keeps out)."""
    ea = run(tmp_path, drift(6.0), 700, {"voi": {"projection_min_lead_s": 0.0}})
    proj = of(ea, "projected-out-of-position")
    assert proj and proj[0].details["lead_s"] < 30 and proj[0].t >= 400, table(*proj)


def test_a_slow_departure_is_projected_well_before_it_leaves(tmp_path):
    """1 m/s across the route from t=400: 150 m off at t=550. Projected from its heading
    once its members' reports show it, at least projection_min_lead_s before it crosses;
    the actual violation is the same story (told again only when twice as bad)."""
    ea = run(tmp_path, drift(1.0), 900)
    proj = of(ea, "projected-out-of-position")
    assert len(proj) == 1, table(*proj)
    p = proj[0]
    assert p.t <= 550 - 30, table(p)   # leads the crossing by the minimum at least
    assert p.details["lead_s"] >= 30 and abs(p.details["projected_t"] - 550) <= 20, p.details
    assert p.category == "constraint-violation-projected" and p.details["projects"] == "out-of-position"
    assert p.details["check"] == "route" and p.details["control_measure"] == "RTE-1"
    assert abs(p.details["rate_mps"] - 1.0) < 0.2 and p.details["distance_m"] < THR
    oop = of(ea, "out-of-position")
    assert oop and oop[0].t > 550 and oop[0].details["projected_at_t"] == p.t, table(*oop)


def test_a_departure_projected_with_less_lead_than_the_minimum_is_not_raised(tmp_path):
    """The slow departure with projection_min_lead_s above what its trend can give (it is
    first put ~120 s ahead): nothing projected, the actual alert at the crossing."""
    ea = run(tmp_path, drift(1.0), 900, {"voi": {"projection_min_lead_s": 200.0}})
    assert not of(ea, "projected-out-of-position"), table(*of(ea, "projected-out-of-position"))
    oop = of(ea, "out-of-position")
    assert oop and 550 <= oop[0].t <= 570, table(*oop)


def test_a_unit_marching_along_its_route_is_not_projected_off_it(tmp_path):
    ea = run(tmp_path, drift(0.0), 900)
    assert not of(ea, "projected-out-of-position") and not of(ea, "out-of-position")


def staggered(unit_entities: tuple[str, ...], where, t0: float, t1: float, period: float) -> list:
    """Each entity reporting every `period` at a phase of its own (period / n apart), 20 m
    apart east-west about where(t): the picture is never of one instant."""
    out = []
    n = len(unit_entities)
    for k, e in enumerate(unit_entities):
        t = t0 + k * period / n
        while t <= t1:
            x, y = where(t)
            out.append(LocationReport(float(t), e, *ll(x + 20.0 * (k - (n - 1) / 2), y)))
            t += period
    return out


FOUR = Force(entities={"A1": ("A1E1", "A1E2", "A1E3", "A1E4"), "A2": ("A2E1", "A2E2"), "B1": ("B1E1", "B1E2")},
             name="projection-lead-staggered")


def _staggered_run(tmp_path, where, t1):
    sc = FOUR.scenario(tmp_path, FEATURES, [mission("A1-move", "A1", "move", route="RTE-1", destination="AA-E")])
    msgs = (staggered(FOUR.entities["A1"], where, 10, t1, 60.0) + FOUR.stays("A2", 0, -3000, 10, t1)
            + [start(100, "A1-move", "A1")])
    return play(sc, msgs, t1)


def test_a_departure_seen_in_part_is_not_projected_from_the_part(tmp_path):
    """Reports every 60 s, a member every 15 s: 3 m/s across the route from t=400 crosses
    150 m at t=450. Until every member has reported twice since, the mean heading and the
    centroid show a fraction of the drift, and a trend of them puts the crossing minutes
    away when it is seconds away (or past): not projected."""
    ea = _staggered_run(tmp_path, drift(3.0), 800)
    assert not of(ea, "projected-out-of-position"), table(*of(ea, "projected-out-of-position"))
    assert of(ea, "out-of-position")


def test_a_unit_back_on_its_route_is_not_projected_off_the_other_side(tmp_path, monkeypatch):
    """A1 goes 300 m south of its route (t=300-450) and comes back at 3 m/s (on it at t=550).
    Dead reckoning carries its members on north past the route until each reports again
    (60 s apart), every member agreeing: the centroid seems to drift off the other side.
    The reports themselves do not move away: nothing is projected. (Without that
    confirmation the same picture would have been.)"""
    where = drift(-2.0, t0=300.0, until=450.0, back=3.0)
    ea = _staggered_run(tmp_path, where, 900)
    after = [a for a in of(ea, "projected-out-of-position") if a.t >= 550]
    assert not after, table(*after)
    monkeypatch.setattr(P, "CONFIRM", -1e9)   # a drift not confirmed by the reports
    ea = _staggered_run(tmp_path / "unconfirmed", where, 900)
    assert [a for a in of(ea, "projected-out-of-position") if a.t >= 550], "the guard was not exercised"


RTE_BEND = line("RTE-BEND", "route", (-500, 0), (2000, 0), (2000, 6000))


def test_a_unit_following_a_bend_in_its_route_is_not_projected_off_it(tmp_path, monkeypatch):
    """RTE-BEND turns north at (2000, 0); A1 marches east at 2 m/s and turns with it at
    t=1100, its members reporting 60 s apart. Until each reports again, dead reckoning
    carries them on east off the new leg, every member agreeing; their reports stay on
    the route: nothing projected. (Without that confirmation it would have been.)"""
    def where(t):
        d = 2.0 * max(0.0, t - 100.0)
        return min(d, 2000.0), max(0.0, d - 2000.0)

    def bend_run(d):
        sc = FOUR.scenario(d, [RTE_BEND, AA_E], [mission("A1-move", "A1", "move", route="RTE-BEND",
                                                          destination="AA-E")])
        msgs = (staggered(FOUR.entities["A1"], where, 10, 1500, 60.0) + FOUR.stays("A2", 0, -3000, 10, 1500)
                + [start(100, "A1-move", "A1")])
        return play(sc, msgs, 1500)
    ea = bend_run(tmp_path)
    assert not of(ea, "projected-out-of-position") and not of(ea, "out-of-position"), table(*ea.alerts)
    monkeypatch.setattr(P, "CONFIRM", -1e9)
    assert of(bend_run(tmp_path / "unconfirmed"), "projected-out-of-position"), "the guard was not exercised"


# ------------------------------------------------------------------------ lateness, penetration
def test_a_late_arrival_is_projected_only_with_the_minimum_lead(tmp_path):
    """A march at 2 m/s to AA-E (8 km) with END-NLT 1500: it cannot make it. Projected late
    from 300 s before the deadline (the horizon), 330 s before the late alert is due; with a
    minimum lead of 400 s, not at all."""
    sc = FORCE.scenario(tmp_path, FEATURES, [mission("A1-move", "A1", "move", route="RTE-1", destination="AA-E",
                                                     end={"type": "END-NLT", "t": 1500})])
    msgs = (FORCE.path("A1", 10, 1600, lambda t: (2.0 * max(0.0, t - 100.0), 0.0)) + FORCE.stays("A2", 0, -3000, 10, 1600)
            + [start(100, "A1-move", "A1")])
    late = of(play(sc, msgs, 1600), "projected-late")
    assert late and 1500 + 30 - late[0].t >= 30, table(*late)
    cfg = config_for(sc, "A", overrides={"voi": {"projection_min_lead_s": 400.0}})
    assert not of(play(sc, msgs, 1600, cfg=cfg), "projected-late")


EDGE_Y = 200.0


def _hostile(tmp_path, speed: float, from_m: float, cfg_overrides: dict | None = None):
    """A1 blocks BP-HOME; H1 heads south at `speed` from `from_m` north of its edge at t=150."""
    sc = FORCE.scenario(tmp_path, FEATURES, [mission("A1-block", "A1", "block", position="BP-HOME", area="BP-HOME")])
    t_in = 150 + from_m / speed
    msgs = (FORCE.stays("A1", 0, -100, 10, 700) + FORCE.stays("A2", 3000, -3000, 10, 700) + [start(100, "A1-block", "A1")]
            + track_path("H1", 150, 700, lambda t: (0.0, EDGE_Y + from_m - speed * (t - 150))))
    cfg = config_for(sc, "A", overrides=cfg_overrides) if cfg_overrides else None
    return alerts_of(play(sc, msgs, 700, cfg=cfg), "projected-penetration"), alerts_of(
        play(sc, msgs, 700, cfg=cfg), "penetration"), t_in


def test_a_penetration_is_projected_only_with_the_minimum_lead(tmp_path):
    """5 m/s from 1.5 km: projected ~120 s (the horizon) before it enters; 20 m/s from
    1 km: in 50 s, within the 30 s a track takes to give a trend and the minimum lead (not
    projected, the penetration told as it comes); a minimum above the horizon: never."""
    proj, pen, t_in = _hostile(tmp_path / "slow", 5.0, 1500.0)
    assert proj and t_in - proj[0].t >= 30 and proj[0].details["lead_s"] >= 30, table(*proj)
    proj, pen, t_in = _hostile(tmp_path / "fast", 20.0, 1000.0)
    assert not proj, table(*proj)
    assert pen and pen[0].t >= t_in, table(*pen)
    proj, pen, t_in = _hostile(tmp_path / "min", 5.0, 1500.0, {"voi": {"projection_min_lead_s": 150.0}})
    assert not proj and pen, table(*proj)


# ------------------------------------------------------------------------ the score
INC = {"owner": "A", "type": "out-of-position", "accept": ["out-of-position"], "subjects": ["A2"],
       "t0": 940.0, "at": 1000.0, "t1": 1060.0, "label": "A2 off route"}


def projected(t: float, typ: str = "projected-out-of-position", projects: str = "out-of-position") -> Alert:
    return Alert(t, "A", typ, "constraint-violation-projected", "priority", ("A2",), "A2 will leave its route",
                 {"projects": projects})


def test_evaluate_counts_projections_after_the_fact_from_when_the_violation_happened():
    """Lead is measured to the oracle's `at` (when it happened), not the window's start t0
    (earlier by the slack for stale reports): a projection between them leads; one at or
    after `at` is after the fact."""
    truth = {"incidents": [INC], "situations": []}
    r = score([projected(700.0), projected(990.0), projected(1000.0), projected(1030.0)], truth)
    p = r["projections"]
    assert p == {"alerts": 4, "false": 0, "after_the_fact": 2, "lead_s": [-30.0, 0.0, 10.0, 300.0],
                 "lead_s_median": 10.0}, p
    assert r["projections_by_type"] == {"projected-out-of-position": {"alerts": 4, "false": 0, "after_the_fact": 2,
                                                                      "lead_s": [-30.0, 0.0, 10.0, 300.0]}}
    assert score([projected(990.0)], truth)["projections"]["after_the_fact"] == 0
    wrong = projected(900.0, "projected-late", "schedule")   # foretells nothing that happened
    p = score([wrong], truth)["projections"]
    assert p["false"] == 1 and p["after_the_fact"] == 0 and p["lead_s"] == []


def test_evaluate_seeds_sums_projections_over_the_seeds():
    def row(seed, leads, late=0):
        return {"seed": seed, "recall": 1.0, "incidents": 10, "alerts": 10, "unwanted": 0, "unwanted_share": 0.0,
                "unwanted_flash": 0, "delay_s_p95": 10.0, "reduction": 60.0, "naive_alerts": 600,
                "naive_unwanted_share": 0.9,
                "projections": {"alerts": len(leads), "false": 0, "after_the_fact": late, "lead_s": leads,
                                "by_type": {"projected-late": {"alerts": len(leads), "false": 0,
                                                               "after_the_fact": late, "lead_s": leads}}}}
    s = summarize([row(1, [40.0, 330.0]), row(2, [-5.0, 35.0, 50.0], late=1)])
    assert s["after_the_fact_total"] == 1 and s["projection_lead_s_median"] == 40.0 and s["projections_total"] == 5
    assert s["projections_by_type"]["projected-late"] == {"alerts": 5, "false": 0, "after_the_fact": 1,
                                                          "lead_s_median": 40.0, "lead_s_min": -5.0}
    assert s["met"]["after_the_fact"] is False and s["met"]["projection_lead"] is True
    for k in ("recall_worst", "unwanted_share_worst", "reduction_total", "targets"):   # the keys it always had
        assert k in s
    s = summarize([row(1, [40.0, 330.0])])
    assert s["met"]["after_the_fact"] and s["after_the_fact_total"] == 0
