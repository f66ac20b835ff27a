"""A block names what it blocks (issue 34.3): `line`, an overlay line no hostile may cross
(a crossing projected before it happens, the crossing itself a penetration), or `area`, a
place no hostile may enter; exactly one of them, each of the right geometry, and nothing
the class does not know: a scenario that breaks this gets one clear error line naming what
is wrong.

Small synthetic scenarios on scenario time, with the builders of tests/synthetic.py
(geometry in local metres east/north of the generator's origin)."""
from __future__ import annotations

import pytest

from saim_mesh import scenario as S

from .synthetic import Force, alerts_of, box, line, mission, near, play, start, track, track_path

FORCE = Force(name="block-line")
write = FORCE.write

BP_HOME = box("BP-HOME", "battle-position", -200, -200, 200, 200)
PASS = line("PL-PASS", "phase-line", (-1500, 600), (1500, 600))        # the avenue's line, 600 m north
BOX_N = box("BOX-N", "area", -400, 500, 400, 900)                      # the place blocked, 500-900 m north
FEATURES = [BP_HOME, PASS, BOX_N]


def stays(unit: str, x: float, y: float, t0: float = 10.0, t1: float = 700.0) -> list:
    return FORCE.stays(unit, x, y, t0, t1)


def _blocking(tmp_path, hostile: list, **what):
    sc = FORCE.scenario(tmp_path, FEATURES, [mission("A1-blk", "A1", "block", position="BP-HOME", **what)])
    return play(sc, stays("A1", 0, 0) + stays("A2", 3000, -3000) + [start(100, "A1-blk", "A1")] + hostile, 700)


def of(ea, typ):
    return alerts_of(ea, typ)


# ============================================================================ a blocked line
def test_a_hostile_across_the_blocked_line_is_a_penetration(tmp_path):
    # 300 m north of the line, then 30 s later 300 m south of it (20 m/s: no trend yet to project)
    ea = _blocking(tmp_path, [track(150, "H1", 0, 900), track(180, "H1", 0, 300), track(210, "H1", 0, 0)],
                   line="PL-PASS")
    pen = of(ea, "penetration")
    assert pen, [(a.t, a.type) for a in ea.alerts]
    assert near(pen[0].t, 180.0) and pen[0].subjects == ("H1",)
    assert pen[0].details["place"] == "PL-PASS" and pen[0].details["mission"] == "A1-blk"
    assert pen[0].priority == "immediate" and pen[0].category == "adversarial-activity"


def test_a_hostile_coming_at_the_blocked_line_steadily_is_projected_to_cross_before_it_does(tmp_path):
    # 5 m/s south from 1.5 km north of the line at t=150: at the line's 50 m strip at t=440
    ea = _blocking(tmp_path, track_path("H1", 150, 600, lambda t: (0.0, 2100.0 - 5.0 * (t - 150))), line="PL-PASS")
    proj = of(ea, "projected-penetration")
    assert proj, [(a.t, a.type) for a in ea.alerts]
    p = proj[0]
    assert p.t <= 440 - 30, p.t   # ahead by at least projection_min_lead_s
    assert p.details["place"] == "PL-PASS" and p.details["projected_t"] > p.t
    assert p.category == "constraint-violation-projected"
    assert not [a for a in of(ea, "penetration") if a.t < p.t]


def test_a_hostile_staying_on_its_side_of_the_blocked_line_is_silent(tmp_path):
    # along the line 1 km north of it, and one sitting 400 m north of it
    ea = _blocking(tmp_path, track_path("H1", 150, 600, lambda t: (-1500.0 + 5.0 * (t - 150), 1600.0))
                   + track_path("H2", 150, 600, lambda t: (0.0, 1000.0)), line="PL-PASS")
    assert not of(ea, "penetration") and not of(ea, "projected-penetration")


def test_a_hostile_inside_the_position_but_short_of_the_line_is_no_penetration_of_the_line(tmp_path):
    """What is blocked is the line, not the position the block is fought from."""
    ea = _blocking(tmp_path, [track(150, "H1", 3000, 3000), track(300, "H1", 0, 0)], line="PL-PASS")
    assert not of(ea, "penetration")


# ============================================================================ a blocked area
def test_a_hostile_entering_the_blocked_area_is_a_penetration(tmp_path):
    ea = _blocking(tmp_path, [track(150, "H1", 0, 2500), track(300, "H1", 0, 700)], area="BOX-N")
    pen = of(ea, "penetration")
    assert pen and near(pen[0].t, 300.0) and pen[0].details["place"] == "BOX-N"


def test_a_hostile_outside_the_blocked_area_is_silent(tmp_path):
    ea = _blocking(tmp_path, track_path("H1", 150, 600, lambda t: (2500.0, 2500.0 - 3.0 * (t - 150))), area="BOX-N")
    assert not of(ea, "penetration") and not of(ea, "projected-penetration")


# ================================================================================ validation
@pytest.mark.parametrize("params, expect", [
    ({"position": "BP-HOME", "line": "PL-PASS", "area": "BOX-N"},
     ["field 'params.line'", "exactly one of area (a place) or line (an avenue), not both"]),
    ({"position": "BP-HOME"}, ["field 'params.area'", "a block names what it blocks", "exactly one of area"]),
    ({"position": "BP-HOME", "line": "BOX-N"}, ["field 'params.line'", "'BOX-N' is a Polygon, not a line"]),
    ({"position": "BP-HOME", "area": "PL-PASS"}, ["field 'params.area'", "'PL-PASS' is a line: give it as line"]),
    ({"position": "BP-HOME", "line": "PL-NOWHERE"}, ["field 'params.line'", "'PL-NOWHERE' is not in the overlay"]),
    ({"position": "BP-HOME", "lines": "PL-PASS"},
     ["field 'params.lines'", "unknown parameter of block", "did you mean 'line'?"]),
], ids=["both", "neither", "line-not-a-line", "area-a-line", "unknown-feature", "unknown-param"])
def test_a_block_that_does_not_name_one_line_or_one_area_is_one_clear_error(tmp_path, params, expect):
    d = write(tmp_path / "sc", FEATURES, [mission("A1-blk", "A1", "block", **params)])
    with pytest.raises(S.ScenarioError) as e:
        S.load(d, events=False)
    msg = str(e.value)
    assert "\n" not in msg and "plans.main[0] (A1-blk)" in msg, msg
    for part in expect:
        assert part in msg, (part, msg)


@pytest.mark.parametrize("what", [{"line": "PL-PASS"}, {"area": "BOX-N"}])
def test_a_block_naming_one_line_or_one_area_loads(tmp_path, what):
    S.load(write(tmp_path / "sc", FEATURES, [mission("A1-blk", "A1", "block", position="BP-HOME", **what)]),
           events=False)
