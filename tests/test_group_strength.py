"""A group told at its whole strength (issue 49.2): hostile tracks of one group reported a
fraction of a second apart, an epoch boundary anywhere among them, make a first alert that
counts them all (ea_agent/domains/suo/detect/assemble.py); members who join later are news,
told at once, not a repeat inside the hostile suppression interval (ea_agent/core/voa.py).

Alert kinds that count entities: a watched area (monitored), a penetration, a contact and
its strength. Small synthetic scenarios on scenario time (tests/synthetic.py)."""
from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from ea_agent.core.alert import Candidate
from ea_agent.core.config import load_config
from ea_agent.core.voa import Voa
from ea_agent.domains.suo.detect.assemble import Assembly

from .synthetic import EPOCH, Force, alerts_of, box, mission, play, start, track
from .test_area_groups import _alerts as area_alerts

FORCE = Force(name="group-strength")
BP_HOME = box("BP-HOME", "battle-position", -200, -200, 200, 200)
BOX_N = box("BOX-N", "area", -600, 500, 600, 1100)   # blocked by A1: no hostile may enter
SPREAD_S = 0.5     # a group's members are reported within this of the first
T0 = 100.0         # near the first member's report, on the epoch grid


@st.composite
def groups(draw) -> tuple[float, list[tuple[float, int]]]:
    """(the first member's report time, [(report time, strength)] of every member): 2-12
    tracks over half a second, the first at any offset to the epoch grid (on it included)."""
    n = draw(st.integers(2, 12))
    off = draw(st.one_of(st.just(0.0), st.floats(0.0, EPOCH, exclude_max=True)))
    first = round(T0 + off, 3)
    later = sorted(draw(st.lists(st.floats(0.0, SPREAD_S), min_size=n - 1, max_size=n - 1)))
    times = [first] + [round(first + d, 3) for d in later]
    strengths = draw(st.lists(st.integers(1, 4), min_size=n, max_size=n))
    return first, list(zip(times, strengths))


def _rows(group, x0: float, y0: float, name: str = "G") -> list[tuple[float, str, float, float, int]]:
    """(t, track, x, y, strength): the group's tracks 20 m apart in a row, each reported at
    its time and every 10 s after."""
    return [(round(t + 10.0 * k, 3), f"{name}-{i}", x0 + 20.0 * i, y0, s)
            for i, (t, s) in enumerate(group) for k in range(6)]


def _reports(group, x0: float, y0: float) -> list:
    return [track(*row) for row in _rows(group, x0, y0)]


def _blocked(tmp_path, hostile: list, until: float = 400.0):
    """Company A's EA: A1 blocks BOX-N from BP-HOME (started at 10), A2 far away."""
    sc = FORCE.scenario(tmp_path, [BP_HOME, BOX_N], [mission("A1-blk", "A1", "block", position="BP-HOME",
                                                             area="BOX-N")])
    units = FORCE.stays("A1", 0, 0, 0.0, until) + FORCE.stays("A2", 0, -8000, 0.0, until)
    return play(sc, units + [start(10, "A1-blk", "A1")] + hostile, until)


# ======================================================================= the first alert
@settings(max_examples=30, deadline=None)
@given(groups())
def test_the_first_watched_area_alert_counts_the_whole_group(g):
    """Hostiles at NAI-SCREEN (watched by BN and by the recon platoon's screen): every key's
    first alert about the group names all its entities and tracks."""
    first, group = g
    total = sum(s for _, s in group)
    got = area_alerts(_rows(group, 2000.0, 17000.0), 300.0)
    firsts = {}
    for a in got:
        firsts.setdefault((a.type, a.details.get("mission")), a)
    assert firsts, "no alert about the group"
    for a in firsts.values():
        assert a.details["strength"] == total and f"{total} entities in {len(group)} tracks" in a.message, \
            (first, group, a.t, a.message)
        assert a.t <= first + 2 * EPOCH + EPOCH   # held voi.group_s (one epoch), given at the epoch's end


@settings(max_examples=30, deadline=None)
@given(groups())
def test_the_first_contact_and_penetration_count_the_whole_group(tmp_path_factory, g):
    """A group reported inside the area A1 blocks, 800 m from it: the penetration and the
    contact each count the whole group at their first alert."""
    first, group = g
    total = sum(s for _, s in group)
    ea = _blocked(tmp_path_factory.mktemp("g"), _reports(group, -100.0, 800.0))
    pen, contact = alerts_of(ea, "penetration"), alerts_of(ea, "contact")
    assert pen and contact, [(a.t, a.type) for a in ea.alerts]
    assert pen[0].details["strength"] == total and f"{total} entities in {len(group)} tracks" in pen[0].message
    assert contact[0].details["strength"] == total and f"Contact: {total} hostile" in contact[0].message
    assert not [a for a in ea.alerts if a.type in ("strength", "proximity") and a.t < first + 90.0], \
        "the group's own members told again as stronger"


# ======================================================================= a group that grows
def test_members_joining_an_area_later_are_told_at_once(tmp_path):
    """Three tracks told at NAI-SCREEN; four more beside them 30 s later, well inside the
    hostile suppression interval: told at once with the seven, at the first alert's priority
    (news, not a progressive repeat)."""
    reps = [(100.0 + 10 * k, f"N-{i}", 2000.0 + 20 * i, 17000.0, 1) for i in range(3) for k in range(20)]
    reps += [(130.3 + 10 * k, f"N-{i}", 2000.0 + 20 * i, 17000.0, 1) for i in range(3, 7) for k in range(17)]
    got = area_alerts(reps, 400.0)
    by_key: dict = {}
    for a in got:
        by_key.setdefault((a.type, a.details.get("mission")), []).append(a)
    assert by_key
    for told in by_key.values():
        assert [a.details["strength"] for a in told] == [3, 7], [(a.t, a.message) for a in told]
        assert told[1].t <= 130.3 + 2 * EPOCH and told[1].priority == told[0].priority
        assert "repeat_of_t" not in told[1].details


def test_members_joining_a_contact_later_are_told_at_once(tmp_path):
    """Six tracks 1 km from A1: one contact counting six; three more beside them 30 s later
    are told at once as a stronger threat (nine), not 90 s later."""
    sc = FORCE.scenario(tmp_path, [], [])
    msgs = FORCE.stays("A1", 0, 0, 0.0, 400.0) + FORCE.stays("A2", 0, -8000, 0.0, 400.0)
    msgs += [track(100.0 + 0.1 * i, f"H-{i}", 1000.0 + 20 * i, 0.0, 1) for i in range(6)]
    msgs += [track(130.0 + 0.1 * i, f"H-{i}", 1000.0 + 20 * i, 0.0, 1) for i in range(6, 9)]
    ea = play(sc, msgs, 400.0)
    contact = alerts_of(ea, "contact")
    assert len(contact) == 1 and contact[0].details["strength"] == 6
    grown = [a for a in ea.alerts if a.type in ("strength", "proximity") and a.details.get("strength") == 9]
    assert grown and grown[0].t <= 130.8 + 2 * EPOCH, [(a.t, a.type, a.message) for a in ea.alerts]


def test_a_track_that_wavers_is_no_growth():
    """The same tracks counting more (a fused track's strength wavers) name no new member:
    judged by the repeat ratio and the suppression interval as before."""
    v = Voa(load_config())
    c = lambda t, n, subj: Candidate(t, "monitored", "immediate", subj, "m", key=("monitored", "NAI", None),
                                     measure=float(n), friendly=False, count=n)
    assert len(v.judge([c(0, 4, ("T1",))])) == 1
    assert v.judge([c(10, 5, ("T1",))]) == []                    # same track, a little stronger
    assert v.judge([c(20, 4, ("T1", "T2"))]) == []               # a new track, no more entities
    assert len(v.judge([c(30, 6, ("T1", "T2"))])) == 1           # more entities, in a new track: news
    assert v.stats["suppressed-time"] == 2


def test_assembly_holds_until_the_group_had_time_and_keeps_the_latest():
    """On event time: due `hold` after the first member's report, the last offer kept, news kept."""
    a = Assembly()
    c1 = Candidate(2.0, "monitored", "immediate", ("T1",), "1", key="k", news=True, count=1,
                   details={"new_tracks": ["T1"]})
    c2 = Candidate(4.0, "monitored", "immediate", ("T1", "T2"), "2", key="k", count=2, details={"new_tracks": []})
    assert a.offer(c1, 2.0, 5.0, first=True) and a.next_due() == 7.0
    assert a.offer(c2, 2.0, 5.0, first=False)                   # held already: replaces it
    assert a.due(6.0) == []
    out = a.due(8.0)
    assert out == [c2] and c2.t == 8.0 and c2.news and c2.details["new_tracks"] == ["T1"]
    assert not a.offer(Candidate(9.0, "monitored", "immediate", ("T3",), "3", key="j"), 1.0, 5.0, first=True)
    assert not a.offer(Candidate(9.0, "monitored", "immediate", ("T3",), "3", key="j"), 9.0, 5.0, first=False)
