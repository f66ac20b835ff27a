"""Key groups of the live mesh (dissemination/streams.py): every data key an EA's interest
matches lies in a group its subscriptions match, over the recorded scenarios' EAs as
they move and over random interests and messages; and an EA fed every message of the
groups it subscribes to raises the in-process run's alerts."""
import pytest
import zenoh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dissemination.exact import exact
from dissemination.interest import Interest
from dissemination.keyspace import KeySpace
from dissemination.streams import Streams
from ea_agent.core.needs import Needs
from ea_agent.domains.suo import make_ea
from ea_agent.domains.suo.needs import TEMPLATES
from ea_agent.domains.uv.messages import UvAgent, UvSighting, UvState
from saim_mesh.protocol import messages as M

ROOT = "t"
ALL_TEMPLATES = (*TEMPLATES, M.SensorHit.KEY, UvState.KEY, UvSighting.KEY, UvAgent.KEY)


def in_groups(subs: set[str]):
    kes = [zenoh.KeyExpr(e) for e in subs]
    return lambda g: any(k.intersects(zenoh.KeyExpr(g)) for k in kes)


def test_each_family_has_its_group():
    s = Streams(ROOT, ALL_TEMPLATES, 2)
    assert s.group("t/pos/X1Y2/x5y9/BN/B/B1/B1S1/E1") == "pos/X1Y2/BN/B"
    assert s.group("t/pos/X1Y2/x5y9/BN/E1") == "pos/X1Y2/BN"          # a path shorter than the depth
    assert s.group("t/pos/X1Y2/x5y9/unknown/E1") == "pos/X1Y2/unknown"
    assert s.group("t/trk/X1Y2/x5y9/N-1") == "trk/X1Y2"
    assert s.group("t/cff/X1Y1/x1y1/A2/CFF-1") == "cff/X1Y1"
    assert s.group("t/msn/A1/A1-move") == "msn/A1"
    assert s.group("t/ord/BN") == "ord/BN" and s.group("t/org/A2") == "org/A2"
    assert s.group("t/hit/g1/s1") == "hit/g1"
    assert s.group("t/st/X1Y1/x1y1/r1") == "st/X1Y1" and s.group("t/sgt/X1Y1/x1y1/r1/tg") == "sgt/X1Y1"
    assert s.group("t/agm/r1/r2") == "agm/r1"


def test_subscriptions_are_coarse_and_do_not_overlap():
    s = Streams(ROOT, ALL_TEMPLATES, 2)
    subs = s.subscriptions({"t/clock", "t/pos/X1Y2/x5y9/**", "t/pos/X1Y2/*/**", "t/trk/X1Y2/*",
                            "t/pos/*/*/BN/A/**", "t/pos/*/*/BN/**", "t/cff/*/*/A2/*", "t/org/**", "t/ord/BN"})
    # the requester of a call for fire is not in its group: every block's
    assert subs == {"pos/X1Y2/**", "trk/X1Y2", "pos/*/BN/**", "cff/*", "org/**", "ord/BN"}
    assert s.subscriptions({"t/*/**"}) == {"**"}


def stream(sc):
    """What the EAs hear, in the in-process run's order: raw hits go to the fusion nodes,
    their tracks to the EAs (`runner.run`)."""
    from saim_mesh.inprocess.runner import Fusion
    fusion = Fusion.of(sc)
    for ev in sc.events:
        if fusion is not None:
            yield from fusion.feed(ev)
            if type(ev) is M.SensorHit:
                continue
        yield ev
    if fusion is not None:
        yield from fusion.flush(sc.duration_s)


def check_run(sc, units, every_s=30.0):
    """Each unit's EA fed the messages of its subscribed groups, re-registering as a peer
    does: every message its interest matches is in them; its alerts; the share it took."""
    ks = KeySpace.of(sc, ROOT)
    streams = Streams.of(ROOT, sc.taskorg, ALL_TEMPLATES)
    out = {}
    for unit in units:
        it = Interest(ks, 3000.0)
        ea = make_ea(sc, unit)
        ea.start(0.0)
        to = sc.taskorg.copy()
        reorgs = sorted((m.start.t, m.params["subject"], m.params["new_parent"]) for m in sc.plan.missions
                        if m.type == "reorganize")
        nxt, fed = 0.0, 0
        fine = heard = None
        for ev in stream(sc):
            if ev.t >= nxt:
                ea.advance(ev.t - 1e-9)
                exprs = it.keys(ea.domain)
                fine, heard = exact(exprs, ROOT), in_groups(streams.subscriptions(exprs))
                nxt = ev.t + every_s
            while reorgs and reorgs[0][0] <= ev.t:
                _, u, p = reorgs.pop(0)
                to.resubordinate(u, p)
            key = ks.key(ev, to, sc.projection)
            if heard(streams.group(key)):
                ea.submit(ev)
                fed += 1
            else:
                assert not fine(key), f"{unit}: {key} matches its interest but not its groups"
        ea.finish(sc.duration_s)
        out[unit] = (ea.alerts, fed)
    return out


@pytest.mark.parametrize("unit", ["A2", "C", "BN"])
def test_an_ea_fed_its_groups_alerts_as_in_process(small, small_run, unit):
    alerts, fed = check_run(small, [unit])[unit]
    assert [a.to_json_dict() for a in alerts] == [a.to_json_dict() for a in small_run[unit].alerts]
    if unit != "BN":   # a platoon or a company does not hear everything
        assert fed < 0.9 * sum(1 for _ in stream(small))


def test_battalion_sensors_groups_cover_every_interest():
    from saim_mesh.inprocess.runner import run
    from saim_mesh.scenario import load
    sc = load("scenarios/battalion-sensors")
    units = ["A1", "B", "BN"]
    got = check_run(sc, units)
    ref = {ea.owner: ea for ea in run(sc, units)}
    for u in units:
        assert [a.to_json_dict() for a in got[u][0]] == [a.to_json_dict() for a in ref[u].alerts], u


# -- random interests and messages -----------------------------------------------------------
@pytest.fixture(scope="module")
def world(small):
    return small, KeySpace.of(small, ROOT), Streams.of(ROOT, small.taskorg, ALL_TEMPLATES)




@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_random_interests_and_messages(world, data):
    sc, ks, streams = world
    to = sc.taskorg.copy()
    units = sorted(to.units)
    # random reorganizations: the keys' paths are cut from the organization as it is now
    for _ in range(data.draw(st.integers(0, 3))):
        u = data.draw(st.sampled_from(units))
        p = data.draw(st.sampled_from(units))
        if u != to.root and p != u and u not in to.ancestors(p):
            to.resubordinate(u, p)
    ox, oy = data.draw(st.floats(520_000.0, 550_000.0)), data.draw(st.floats(3_880_000.0, 3_910_000.0))   # small's UTM zone
    cx = lambda: ox + data.draw(st.floats(-20_000.0, 20_000.0))   # noqa: E731
    cy = lambda: oy + data.draw(st.floats(-20_000.0, 20_000.0))   # noqa: E731
    some = lambda: frozenset(data.draw(st.lists(st.sampled_from(units), max_size=4)))   # noqa: E731
    by = {"path": frozenset(to.path(u) for u in some()), "unit": some(), "issuer": some(), "requester": some()}
    if data.draw(st.booleans()):
        by["cff"] = frozenset({"CFF-1", "CFF-2"})
    circles = tuple((cx(), cy(), data.draw(st.floats(100.0, 9000.0))) for _ in range(data.draw(st.integers(0, 3))))
    boxes = []
    for _ in range(data.draw(st.integers(0, 2))):
        x0, y0 = cx(), cy()
        boxes.append((x0, y0, x0 + data.draw(st.floats(0.0, 12000.0)), y0 + data.draw(st.floats(0.0, 12000.0))))
    whole = tuple(data.draw(st.lists(st.sampled_from(["org", "msn", "ord"]), max_size=2, unique=True)))
    only = ((M.SensorTrack.KEY, (boxes[0],)),) if boxes and data.draw(st.booleans()) else ()
    needs = Needs(TEMPLATES, by=by, circles=circles, boxes=tuple(boxes[1:]), whole=whole, only=only)
    exprs = Interest(ks, 3000.0).of(needs)
    fine, heard = exact(exprs, ROOT), in_groups(streams.subscriptions(exprs))
    ents = sorted(to.entity_unit)
    for _ in range(30):
        x, y = cx(), cy()
        lon, lat = sc.projection.to_lonlat(x, y)
        u = data.draw(st.sampled_from(units))
        msg = data.draw(st.sampled_from([
            M.LocationReport(1.0, data.draw(st.sampled_from(ents)), lon, lat),
            M.SensorTrack(1.0, "N-1", lon, lat, 3),
            M.MissionConfirm(1.0, "m1", u, "start"),
            M.Order(1.0, "execute-plan", "p", u),
            M.CallForFire(1.0, data.draw(st.sampled_from(["CFF-1", "CFF-3"])), u, lon, lat, 300.0),
            M.Reorganization(1.0, u, to.root)]))
        key = ks.key(msg, to, sc.projection)
        assert heard(streams.group(key)) or not fine(key), f"{key} matches the interest, not its groups"
