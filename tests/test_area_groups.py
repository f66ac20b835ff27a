"""Watched areas tell a new hostile group once: a halted group whose reports flicker at the
area's edge is not a new group each time it comes back inside, and a track that appears
beside one already there reinforces it (ea_agent/domains/suo/detect/areas.py)."""
from __future__ import annotations

from ea_agent.domains.suo.generator import ORIGIN_LONLAT
from ea_agent.domains.suo.messages import SensorTrack
from saim_mesh import scenario as S
from saim_mesh.inprocess.runner import config_for, make_ea

from .conftest import SMALL
from .heard import by_live_groups

EDGE_X = 4000.0   # NAI-SCREEN (watched by the recon platoon's screen) spans x 0..4000, y 15500..19000


def _tracks(reports) -> list:
    """Track messages from the reports [(t, id, x, y, strength)], local metres."""
    sc = S.load(SMALL, events=False)
    ox, oy = sc.projection.to_xy(*ORIGIN_LONLAT)
    out = []
    for t, k, x, y, s in sorted(reports):
        lon, lat = sc.projection.to_lonlat(ox + x, oy + y)
        out.append(SensorTrack(t, k, float(lon), float(lat), s, at=t))
    return out


def _alerts(reports, until, heard_by_peer: bool = False):
    """BN's alerts about NAI-SCREEN from the track reports [(t, id, x, y, strength)], local
    metres: all of them (an in-process EA), or (`heard_by_peer`) what BN's live peer hears
    of them by its key groups (`heard.by_live_groups`)."""
    sc = S.load(SMALL, events=False)
    ea = make_ea(sc, "BN", config_for(sc, "BN"))
    ea.start(0.0)
    msgs = _tracks(reports)
    if heard_by_peer:
        heard = by_live_groups(sc, msgs, "BN")
        assert len(heard) < len(msgs), "the peer heard everything: the test shows nothing"
        msgs = heard
    for m in msgs:
        ea.submit(m)
    ea.finish(until)
    return [a for a in ea.alerts if "NAI-SCREEN" in a.details.get("places", ())]


def test_a_halted_group_flickering_at_the_edge_is_told_once():
    """Inside, then reported 40 m outside for 15 min (longer than the alert expiry), then
    inside again: the same group that never left, told once."""
    reps = [(t, "N-1", EDGE_X - 30, 17000.0, 4) for t in range(100, 200, 10)]
    reps += [(t, "N-1", EDGE_X + 40, 17000.0, 4) for t in range(200, 1100, 10)]
    reps += [(t, "N-1", EDGE_X - 30, 17000.0, 4) for t in range(1100, 1300, 10)]
    got = _alerts(reps, 1300.0)
    assert len(got) == 1 and got[0].t < 200


def test_a_group_that_went_away_and_came_back_is_news():
    """The same track 1 km away for 15 min, then back inside: a new arrival, told again
    (the edge rule above does not hide real comings and goings)."""
    reps = [(t, "N-1", EDGE_X - 30, 17000.0, 4) for t in range(100, 200, 10)]
    reps += [(t, "N-1", EDGE_X + 1000, 17000.0, 4) for t in range(200, 1100, 10)]
    reps += [(t, "N-1", EDGE_X - 30, 17000.0, 4) for t in range(1100, 1300, 10)]
    got = _alerts(reps, 1300.0)
    assert len(got) == 2 and got[1].t >= 1100


def test_a_track_beside_one_already_there_is_no_new_group():
    """A second track 80 m from a group already in the area is that group reinforced: not
    news as a new group; a track 2 km away is."""
    reps = [(t, "N-1", 2000.0, 17000.0, 4) for t in range(100, 600, 10)]
    reps += [(t, "N-2", 2080.0, 17000.0, 4) for t in range(300, 600, 10)]
    reps += [(t, "N-3", 2000.0, 15800.0, 4) for t in range(450, 600, 10)]
    got = _alerts(reps, 600.0)
    news = [k for a in got for k in a.details.get("new_tracks", ())]
    assert "N-1" in news and "N-3" in news and "N-2" not in news


def test_a_group_that_stood_inside_until_it_left_is_no_news_back_whatever_else_is_heard():
    """Reported inside once at t=100 and standing there, 1 km out at 900, back at 1000: it
    was in the area until 900, so its return is no news (the expiry is 720 s). The time a
    track was last inside is stamped when it changes and at the periodic scan, not at
    every epoch another track's change closed: with a far track reported every 2 s (which
    an in-process EA hears and a peer does not) the alerts are the same, and without it
    the return was told as a new group."""
    reps = [(100, "N-1", EDGE_X - 500, 17000.0, 4), (900, "N-1", EDGE_X + 1000, 17000.0, 4),
            (1000, "N-1", EDGE_X - 500, 17000.0, 4)]
    far = [(t, "F-9", -30000.0 + 5 * t, 40000.0, 4) for t in range(101, 1300, 2)]
    alone, beside = _alerts(reps + far, 1300.0, heard_by_peer=True), _alerts(reps + far, 1300.0)
    assert [a.to_json_dict() for a in alone] == [a.to_json_dict() for a in beside]
    assert len(alone) == 1 and alone[0].t < 200, [(a.t, a.type, a.details.get("new_tracks")) for a in alone]
