"""Zone and area reconnaissance progress (the share of the area seen, or of the zone's
depth passed, against the share of the time gone, and at the end), and fratricide inside a passage of lines' lane (the
passing unit is expected in the passed unit's boundary there, and only there).

Synthetic scenarios on scenario time, with the builders of test_check_families."""
from __future__ import annotations

import pytest

from ea_agent.domains.suo.detect.recon import RECHECK_S
from saim_mesh import scenario as scenarios

from .synthetic import along
from .test_check_families import EPOCH, box, end, mission, of, path, play, scenario, start, stays, write

ZONE = box("ZONE-Z", "area", 0, 0, 2000, 1000)          # 2 km x 1 km: 8 x 4 cells of 250 m
SCREEN = box("SCREEN-Z", "area", -100, -100, 2100, 1100)


def sweep(t0: float, t1: float):
    """A boustrophedon over ZONE-Z in lanes 500 m apart, finishing at t1."""
    legs = [(0, 250, 2000, 250), (2000, 250, 2000, 750), (2000, 750, 0, 750)]
    total = sum(abs(x1 - x0) + abs(y1 - y0) for x0, y0, x1, y1 in legs)

    def where(t):
        return along(legs, max(0.0, min(1.0, (t - t0) / (t1 - t0))) * total)
    return where


def recon(typ: str, **params) -> dict:
    return mission("A1-recon", "A1", typ, {"type": "START-AT", "t": 100}, {"type": "END-NLT", "t": 1300},
                   position="SCREEN-Z", area="ZONE-Z", **params)


@pytest.mark.parametrize("typ", ["zone-reconnaissance", "area-reconnaissance"])
def test_a_reconnaissance_that_stays_in_a_corner_falls_behind(tmp_path, typ):
    sc = scenario(tmp_path, [ZONE, SCREEN], [recon(typ)])
    ea = play(sc, stays("A1", 100, 100, 10, 1300) + stays("A2", 0, -3000, 10, 1300) + [start(100, "A1-recon", "A1")],
              1300)
    rp = [a for a in of(ea, "recon-progress") if a.details["check"] == "behind"]
    assert rp, [a.type for a in ea.alerts]
    a = rp[0]
    # the corner within 400 m of (100, 100) is 4 of 32 cells (12.5 %): an area reconnaissance
    # is 25 % behind once more than 37.5 % of the 1200 s is gone (t > 550); a zone
    # reconnaissance has passed none of its depth (no band across it seen), behind once more
    # than 25 % is gone (t > 400); judged on a 30 s re-check
    got, due = (4 / 32, 550) if typ == "area-reconnaissance" else (0.0, 400)
    assert due < a.t <= due + RECHECK_S + 2 * EPOCH + 5, a.t
    assert a.subjects == ("A1",) and a.priority == "priority" and a.category == "plan-constraint-violated"
    assert a.details["mission"] == "A1-recon" and a.details["area"] == "ZONE-Z"
    assert a.details["seen"] == pytest.approx(got, abs=0.01)
    assert "behind" in a.message and "ZONE-Z" in a.message


def test_an_area_reconnaissance_that_sweeps_its_area_on_time_is_silent(tmp_path):
    """Lanes along its length: coverage in time (a zone's depth is passed front to rear
    instead: tests/test_mission_classes.py)."""
    sc = scenario(tmp_path, [ZONE, SCREEN], [recon("area-reconnaissance")])
    msgs = path("A1", 100, 1250, sweep(100, 1200)) + stays("A2", 0, -3000, 10, 1300) + \
        [start(100, "A1-recon", "A1"), end(1260, "A1-recon", "A1")]
    ea = play(sc, msgs, 1300)
    assert not of(ea, "recon-progress"), [a.message for a in of(ea, "recon-progress")]
    assert ea.domain.recon.watch == {}   # its monitor ended with the mission


def test_an_incomplete_reconnaissance_is_told_at_its_end(tmp_path):
    """It sweeps only the southern lane, fast enough never to trail by 25 % of its cells, then ends."""
    sc = scenario(tmp_path, [ZONE, SCREEN], [recon("area-reconnaissance", by=5000)])
    msgs = path("A1", 100, 600, lambda t: (min(2000.0, (t - 100) * 4), 250.0)) + \
        stays("A2", 0, -3000, 10, 900) + [start(100, "A1-recon", "A1"), end(700, "A1-recon", "A1")]
    ea = play(sc, msgs, 900)
    rp = of(ea, "recon-progress")
    assert [a.details["check"] for a in rp] == ["incomplete"], [a.message for a in rp]
    assert 700 <= rp[0].t <= 700 + 2 * EPOCH
    assert 0.3 < rp[0].details["seen"] < 0.9


def test_recon_by_must_be_a_time(tmp_path):
    with pytest.raises(scenarios.ScenarioError, match="by"):
        scenarios.load(write(tmp_path / "bad", [ZONE, SCREEN], [recon("zone-reconnaissance", by="soon")]), events=False)


# ---------------------------------------------------------------- passage of lines and fratricide
# A's boundary west of x=0, B's east of it; B1 sits at (600, 0); A1 passes B1 through LANE-AB.
BND_A = box("BND-A", "boundary", -5000, -5000, 0, 5000)
BND_B = box("BND-B", "boundary", 0, -5000, 5000, 5000)
LANE = box("LANE-AB", "area", 0, -100, 1200, 100)
CP = box("CP-AB", "checkpoint", 500, -100, 700, 100)
ATTRS = {"A": {"boundary": "BND-A"}, "B": {"boundary": "BND-B"}, "BN": {"weapons_range_m": 1000.0}}


def passage(**extra) -> list[dict]:
    return [mission("A1-pass", "A1", "passage-of-lines", None, None, partner="B1", point="CP-AB", at=400,
                    **extra)]


def test_a_unit_passing_inside_its_lane_is_no_fratricide_risk(tmp_path):
    sc = scenario(tmp_path, [BND_A, BND_B, LANE, CP], passage(lane="LANE-AB"), attrs=ATTRS)
    msgs = stays("B1", 600, 0, 10, 600) + stays("A2", -3000, 0, 10, 600) + \
        path("A1", 10, 600, lambda t: (-500 + t * 2, 0.0))   # through the lane's middle
    ea = play(sc, msgs, 600)
    assert not of(ea, "fratricide"), [a.message for a in of(ea, "fratricide")]


def test_a_passing_unit_outside_its_lane_is_a_fratricide_risk(tmp_path):
    sc = scenario(tmp_path, [BND_A, BND_B, LANE, CP], passage(lane="LANE-AB"), attrs=ATTRS)
    msgs = stays("B1", 600, 0, 10, 600) + stays("A2", -3000, 0, 10, 600) + \
        path("A1", 10, 600, lambda t: (-500 + t * 2, 400.0))  # 300 m north of the lane
    ea = play(sc, msgs, 600)
    fr = of(ea, "fratricide")
    assert fr and fr[0].priority == "flash", [a.type for a in ea.alerts]
    assert {"A1", "B1"} <= set(fr[0].subjects)
    assert fr[0].details["outside_boundary"] == ["A1"]
    assert 250 <= fr[0].t <= 262   # A1 crosses into B's boundary at t=250


def test_without_a_passage_the_same_move_is_a_fratricide_risk(tmp_path):
    """The relaxation belongs to the passage: the same track with no passage planned alerts."""
    sc = scenario(tmp_path, [BND_A, BND_B, LANE, CP], [], attrs=ATTRS)
    msgs = stays("B1", 600, 0, 10, 600) + stays("A2", -3000, 0, 10, 600) + \
        path("A1", 10, 600, lambda t: (-500 + t * 2, 0.0))
    ea = play(sc, msgs, 600)
    assert of(ea, "fratricide")


def test_after_the_passage_ends_its_lane_no_longer_excuses(tmp_path):
    sc = scenario(tmp_path, [BND_A, BND_B, LANE, CP], passage(lane="LANE-AB"), attrs=ATTRS)
    msgs = stays("B1", 600, 0, 10, 900) + stays("A2", -3000, 0, 10, 900) + \
        stays("A1", -500, 0, 10, 300) + [start(20, "A1-pass", "A1"), end(300, "A1-pass", "A1")] + \
        path("A1", 310, 900, lambda t: (-500 + (t - 300) * 2, 0.0))
    ea = play(sc, msgs, 900)
    fr = of(ea, "fratricide")
    assert fr and fr[0].t >= 550, [(a.t, a.message) for a in fr]
