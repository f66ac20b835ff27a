"""An EA depends only on the sources its interest needs (issue 31.2), and fed only those
sources' shares of a recorded battle it raises exactly what it raises hearing everything."""
from pathlib import Path

import pytest

from saim_mesh import scenario as S
from saim_mesh.live.depend import Share, cp_shares, depends
from saim_mesh.live.play import share
from saim_mesh.scenario import mesh_units
from saim_mesh.inprocess.runner import config_for, make_ea

ROOT = Path(__file__).resolve().parents[1]


def _ea(sc, unit):
    ea = make_ea(sc, unit, config_for(sc, unit))
    ea.start(0.0)
    return ea


@pytest.fixture(scope="module")
def battalion():
    return S.load(str(ROOT / "scenarios" / "battalion"))


def test_shares_cover_every_unit_once(battalion):
    to = battalion.taskorg
    seen: dict[str, str] = {}
    for name, sh in cp_shares(battalion).items():
        for u in sh.carries(to):
            assert u not in seen, f"{u} in both {seen[u]} and {name}"
            seen[u] = name
    assert set(seen) == set(to.units)
    assert [n for n, sh in cp_shares(battalion).items() if sh.tracks] == [f"cp.{to.root}"]


def test_a_company_does_not_depend_on_a_distant_company(battalion):
    deps = {u: depends(battalion, _ea(battalion, u), sorted(cp_shares(battalion))) for u in ("BN", "A", "C", "C2")}
    assert deps["BN"] == sorted(cp_shares(battalion))           # the battalion watches everything
    assert "cp.C" not in deps["A"] and "cp.A" not in deps["C"]   # A and C are not neighbours
    assert {"cp.C", "cp.BN"} <= set(deps["C2"])                  # its own company; the tracks
    assert depends(battalion, _ea(battalion, "C"), ["cp.C", "other"]) == ["cp.C", "other"]   # unknown: depended on


def test_the_sources_depended_on_give_the_same_alerts(battalion):
    shares = cp_shares(battalion)
    streams = {n: {id(m) for m in share(battalion, list(sh.units) if sh.units else None, sh.tracks, list(sh.but))}
               for n, sh in shares.items()}
    for u in mesh_units(battalion):
        full, part = _ea(battalion, u), _ea(battalion, u)
        heard = set().union(*(streams[s] for s in depends(battalion, part, sorted(shares))))
        for m in battalion.events:
            full.submit(m)
            if id(m) in heard:
                part.submit(m)
        full.finish(battalion.duration_s)
        part.finish(battalion.duration_s)
        assert [(a.t, a.type, a.message) for a in part.alerts] == [(a.t, a.type, a.message) for a in full.alerts], u


def test_share_args_round_trip():
    assert Share(("A",)).args() == ["--units", "A"]
    assert Share(None, ("A", "B"), tracks=True).args() == ["--but", "A", "B", "--tracks"]
