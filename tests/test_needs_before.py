"""A message judged on places beyond a peer's interest (a call for fire, judged on every
position near its target): the domain says what must be up to date first
(`needs_before`), the situation store gives each of those keys' latest entry before the
message, and the peer's EA then raises what an in-process EA, which hears everything,
raises (brigade 2C2, 2CFF-3 at t=3172: friendlies of another company near the target)."""
from __future__ import annotations

from bisect import bisect_left
from dataclasses import replace

import numpy as np
import pytest

from dissemination.exact import exact
from dissemination.interest import Interest
from dissemination.keyspace import KeySpace, Template, matcher
from ea_agent.domains.suo import make_ea
from saim_mesh.protocol import messages as M
from saim_mesh.inprocess.runner import run

ROOT = "t"


def _keys(sc, events) -> list[str]:
    """Each event's key, with the task organization as it is at its time (as the replay)."""
    ks = KeySpace(ROOT)
    to = sc.taskorg.copy()
    reorgs = sorted((m.start.t, m.params["subject"], m.params["new_parent"]) for m in sc.plan.missions
                    if m.type == "reorganize")
    out = []
    for ev in events:
        while reorgs and reorgs[0][0] <= ev.t:
            _, u, p = reorgs.pop(0)
            to.resubordinate(u, p)
        out.append(ks.key(ev, to, sc.projection))
    return out


def peer_run(sc, unit: str, events: list, prefetch: bool = True):
    """An EA fed as a peer is: only what its interest (re-registered every 30 s) covers
    and, before a message its domain names, each needed key's latest entry from the store."""
    ks = KeySpace(ROOT)
    it = Interest(ks, 3000.0)
    keys = _keys(sc, events)
    by_key: dict[str, list[int]] = {}
    for i, k in enumerate(keys):
        by_key.setdefault(k, []).append(i)
    ea = make_ea(sc, unit)
    ea.start(0.0)
    want, nxt, fetched = (lambda k: False), 0.0, 0
    for i, ev in enumerate(events):
        if ev.t >= nxt:
            ea.advance(ev.t - 1e-9)
            want = exact(it.keys(ea.domain), ROOT)
            nxt = ev.t + 30.0
        if not want(keys[i]):
            continue
        needs = ea.domain.needs_before(ev) if prefetch else None
        if needs is not None:
            match = matcher(sorted(it.of(needs)))
            latest = sorted(js[h - 1] for k, js in by_key.items() if match(k) and (h := bisect_left(js, i)))
            for j in latest:
                ea.submit(events[j])
            fetched += len(latest)
        ea.submit(ev)
    ea.finish(sc.duration_s)
    return ea, fetched


def _far_call(sc, requester: str, target_unit: str, t: float) -> tuple[list, M.CallForFire]:
    """The scenario's events with a call for fire by `requester` at `t` on where
    `target_unit`'s first entity last reported (far outside the requester's interest)."""
    ent = sorted(e for e, u in sc.taskorg.entity_unit.items() if sc.taskorg.path(u).startswith(
        sc.taskorg.path(target_unit)))[0]
    last = [e for e in sc.events if type(e) is M.LocationReport and e.entity == ent and e.t < t][-1]
    cff = M.CallForFire(t, "CFF-far", requester, last.lon, last.lat, 600.0)
    evs = list(sc.events)
    at = next(i for i, e in enumerate(evs) if e.t > t)
    return evs[:at] + [cff] + evs[at:], cff


def test_a_call_for_fire_is_judged_on_the_positions_around_its_target(small):
    evs, cff = _far_call(small, "A2", "C3", 3000.5)
    sc = replace(small, events=evs)
    (ref,) = run(sc, ["A2"])
    want = [a.to_json_dict() for a in ref.alerts]
    assert any(a["type"] == "call-for-fire" and a["details"]["cff"] == "CFF-far" for a in want)
    got, fetched = peer_run(sc, "A2", evs)
    assert fetched > 0 and [a.to_json_dict() for a in got.alerts] == want
    blind, _ = peer_run(sc, "A2", evs, prefetch=False)   # without: the friendlies there are unknown
    assert not any(a.type == "call-for-fire" and a.details["cff"] == "CFF-far" for a in blind.alerts)


def test_needs_before_names_the_target_surroundings_and_the_entities_believed_there(small):
    ea = make_ea(small, "A2")
    ea.start(0.0)
    for ev in small.events:
        if ev.t > 600.0:
            break
        ea.submit(ev)
    ea.advance(600.0)
    dom = ea.domain
    pic = dom.pic
    i = next(i for i, u in enumerate(pic.ent_leaf) if u.startswith("B1") and not np.isnan(pic.xy[i, 0]))
    lon, lat = pic.lon[i], pic.lat[i]
    assert dom.needs_before(M.CallForFire(601.0, "X", "A3", lon, lat, 600.0)) is None   # not ours to judge
    assert dom.needs_before(M.LocationReport(601.0, pic.ents[i], lon, lat)) is None
    needs = dom.needs_before(M.CallForFire(601.0, "X", "A2", lon, lat, 600.0))
    x, y = pic.proj.to_xy(lon, lat)
    assert needs.circles == ((pytest.approx(float(x)), pytest.approx(float(y)), 600.0),)
    assert pic.ents[i] in needs.by["entity"] and not any(pic.ent_leaf[pic.eidx[e]] in dom.own_leaves
                                                        for e in needs.by["entity"])
    keys = Interest(KeySpace(ROOT), 3000.0).of(needs)
    assert f"{ROOT}/pos/*/*/**/{pic.ents[i]}" in keys
    place = KeySpace(ROOT).place(float(x), float(y))
    assert f"{ROOT}/pos/{place}/**" in keys and not any("/msn/" in k or "/ord/" in k for k in keys)


def test_a_template_binds_a_field_after_its_path():
    t = Template("pos/{place}/{path:entity}/{entity}")
    assert t.expr({"entity": "E1"}) == "pos/*/*/**/E1"
    assert t.expr({"path": "BN/A"}) == "pos/*/*/BN/A/**"   # unchanged: nothing after the path bound


def test_the_watchman_drops_a_report_older_than_one_it_took(small):
    ea = make_ea(small, "A2")
    ea.start(0.0)
    ea.submit(M.LocationReport(10.0, "A2S1E01", -116.60, 35.20))
    ea.submit(M.LocationReport(5.0, "A2S1E01", -116.50, 35.30))   # a store's older report, fed late
    ea.advance(12.0)
    pic = ea.domain.pic
    assert pic.lon[pic.eidx["A2S1E01"]] == -116.60 and ea.domain.watchman.stats["stale"] == 1


def test_the_store_matcher_takes_an_entity_wherever_it_is_as_zenoh_does():
    import zenoh
    exprs = ["r/pos/*/*/**/E1", "r/pos/X1Y1/x1y1/**", "r/pos/*/*/BN/A/**/E2"]
    keys = ["r/pos/X0Y0/x0y0/BN/A/A1/E1", "r/pos/X0Y0/x0y0/E1", "r/pos/X0Y0/E1", "r/trk/X0Y0/x0y0/E1",
            "r/pos/X0Y0/x0y0/BN/B/E2", "r/pos/X0Y0/x0y0/BN/A/A1/E2", "r/pos/X1Y1/x1y1/BN/E3", "r/pos/X0Y0/x0y0/BN/E11"]
    match = matcher(exprs)
    kes = [zenoh.KeyExpr(e) for e in exprs]
    for k in keys:
        assert match(k) == any(zenoh.KeyExpr(k).intersects(x) for x in kes), k
