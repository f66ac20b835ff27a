"""Dissemination without processes: an EA fed only what its subscriptions match
raises exactly the alerts of one fed everything."""
import pytest
import zenoh

from dissemination.interest import Interest
from dissemination.keyspace import KeySpace, block_of, cell, cells_within
from ea_agent.domains.suo import make_ea
from saim_mesh.protocol import messages


def test_keys_and_cells():
    ks = KeySpace("saim/x")
    assert cell(4100.0, -1.0) == "x2y-1" and block_of("x2y-1") == "X0Y-1" and block_of("x268y1950") == "X67Y487"
    assert cells_within(1000.0, 1000.0, 1500.0) == {f"x{i}y{j}" for i in (-1, 0, 1) for j in (-1, 0, 1)}
    for bad in ("", "/saim", "a//b", "a/*"):
        with pytest.raises(ValueError):
            KeySpace(bad)
    assert ks.key(messages.MissionConfirm(1.0, "m", "A1", "start"), None, None) == "saim/x/msn/A1/m"


def filtered_run(sc, unit):
    ks = KeySpace("t")
    it = Interest(ks, 3000.0)
    ea = make_ea(sc, unit)
    ea.start(0.0)
    to = sc.taskorg.copy()
    reorgs = sorted((m.start.t, m.params["subject"], m.params["new_parent"]) for m in sc.plan.missions
                    if m.type == "reorganize")
    kes, nxt, fed = [], 0.0, 0
    for ev in sc.events:
        if ev.t >= nxt:
            ea.advance(ev.t - 1e-9)
            kes = [zenoh.KeyExpr(k) for k in it.keys(ea.domain)]
            nxt = ev.t + 30.0   # as often as a peer re-registers
        while reorgs and reorgs[0][0] <= ev.t:
            _, u, p = reorgs.pop(0)
            to.resubordinate(u, p)
        k = zenoh.KeyExpr(ks.key(ev, to, sc.projection))
        if any(k.intersects(x) for x in kes):
            ea.submit(ev)
            fed += 1
    ea.finish(sc.duration_s)
    return ea.alerts, fed


@pytest.mark.parametrize("unit", ["A2", "C"])
def test_subscriptions_are_sufficient_and_selective(small, small_run, unit):
    alerts, fed = filtered_run(small, unit)
    assert [a.to_json_dict() for a in alerts] == [a.to_json_dict() for a in small_run[unit].alerts]
    assert fed < {"A2": 0.5, "C": 0.8}[unit] * len(small.events)   # a platoon or company does not take everything


def test_store_matcher_agrees_with_zenoh():
    from dissemination.keyspace import matcher as _matcher
    exprs = ["r/pos/X1Y2/x5y9/**", "r/trk/X1Y2/*", "r/msn/A1/*", "r/pos/*/*/BN/A/**", "r/cff/*/*/A2/*"]
    keys = ["r/pos/X1Y2/x5y9/BN/B/B1/B1S1/E1", "r/pos/X1Y2/x5y8/BN/B/B1/B1S1/E1", "r/trk/X1Y2/x5y9/N-1",
            "r/trk/X1Y2/N-1", "r/msn/A1/A1-move", "r/msn/A1/x/y", "r/pos/X0Y0/x1y1/BN/A/A1/A1S1/E2",
            "r/cff/X1Y1/x1y1/A2/CFF-1", "r/cff/X1Y1/x1y1/A3/CFF-1", "r/ord/BN"]
    match = _matcher(exprs)
    kes = [zenoh.KeyExpr(e) for e in exprs]
    for k in keys:
        assert match(k) == any(zenoh.KeyExpr(k).intersects(x) for x in kes), k


def test_dissemination_parameters_come_from_the_config(small, tmp_path):
    """Radius and block coarsening are config, overridable per EA: a wider radius takes
    more cells, and a block share above 16 never takes a whole block."""
    from ea_agent.core.config import DEFAULT_PATH, load_config
    text = DEFAULT_PATH.read_text() + "\n[ea.A2.dissemination]\nradius_m = 6000.0\nblock_share = 17\n"
    (tmp_path / "ea.toml").write_text(text)
    base, wide = load_config(None, "A2")["dissemination"], load_config(tmp_path / "ea.toml", "A2")["dissemination"]
    assert base["radius_m"] == 3000.0 and wide == {**base, "radius_m": 6000.0, "block_share": 17}
    ea = make_ea(small, "A2")
    ea.start(0.0)
    for ev in small.events:
        if ev.t > 60.0:
            break
        ea.submit(ev)   # the units' positions are known
    ea.advance(60.0)
    ks = KeySpace("t")
    geo = lambda keys: {k.split("/")[3] for k in keys if k.startswith("t/pos/") and "/BN" not in k}
    near = geo(Interest(ks, base["radius_m"], 17).keys(ea.domain))
    far = geo(Interest(ks, wide["radius_m"], wide["block_share"]).keys(ea.domain))
    coarse = geo(Interest(ks, base["radius_m"], 1).keys(ea.domain))
    assert "*" not in far and len(far) > len(near) > 0   # cell by cell, and more cells when wider
    assert coarse == {"*"}                               # t/pos/<block>/*/** : whole blocks only
