"""The brigade scenario (issue 14, 1): its structure, determinism, ground truth met by the
EAs, and on-demand generation. Fast: the full brigade is only built (no events), the
rest runs on brigade-small."""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from ea_agent.core.scenario import ScenarioError, check_key_chunk
from ea_agent.domains import suo
from ea_agent.domains.suo import brigade as B
from saim_mesh import ondemand
from saim_mesh import scenario as S
from saim_mesh.inprocess.evaluate import evaluate

from .conftest import BATTALION

FILES = ("scenario.json", "plan.json", "overlay.geojson", "events.jsonl.gz", "truth.json")


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> Path:
    return ondemand.ensure("brigade-small", tmp_path_factory.mktemp("ondemand"))


@pytest.fixture(scope="module")
def small_sc(made):
    return S.load(made)


def _ancestors(units: dict, u: str) -> list[str]:
    out = []
    while units[u]["parent"] is not None:
        u = units[u]["parent"]
        out.append(u)
    return out


@pytest.mark.parametrize("small", [False, True])
def test_structure_three_battalions_and_troops_under_bde(small):
    b = B.build(small=small, seed=7)
    units = {u["id"]: u for u in b.units}
    assert len(units) == len(b.units), "unit ids repeat"
    assert units["BDE"]["echelon"] == "brigade" and units["BDE"]["parent"] is None
    bns = sorted(u for u, d in units.items() if d["echelon"] == "battalion")
    assert bns == ["1BN", "2BN", "3BN"] and all(units[u]["parent"] == "BDE" for u in bns)
    troops = [u for u, d in units.items() if d["echelon"] == "company" and d["parent"] == "BDE"]
    assert sorted(troops) == ["CAV", "FA", "SPT"]
    for u in units:   # troops and everything under them belong to no battalion
        under = _ancestors(units, u)
        if set(under) & set(troops):
            assert not set(under) & set(bns), u
    for u in ("1A1S1", "2B3S4", "3M2", "3C"):
        assert {"1": "1BN", "2": "2BN", "3": "3BN"}[u[0]] in _ancestors(units, u)
    ents = list(b.entity_leaf)
    assert len(set(ents)) == len(ents)
    for x in [*units, *ents, *b.hostiles]:
        check_key_chunk(x, "brigade", "id")   # raises on / * $ # ? or a space
    n = len(ents)
    assert (3800 <= n <= 4300) if not small else (250 <= n <= 500), n


def test_every_battalion_gets_incidents_of_its_own():
    b = B.build(small=False, seed=7)
    kinds = [p.sim.incidents for p in b.battalions]
    assert kinds == ["scripted", "random", "random"]
    assert b.battalions[1].sim.drawn != b.battalions[2].sim.drawn
    assert all(p.sim.order is None for p in b.battalions)   # no battalion switches the brigade's plan
    for pre in B.BATTALIONS:
        assert any(h.startswith(pre + "H") for h in b.hostiles), pre
    # what the oracle reads of the orders is renamed as the events are: 1BN orders 1M's march at 2150
    assert {"t": 2150.0, "mission": "1M-march", "phase": "start", "issuer": "1BN"} in b.mission_orders
    assert all(o["mission"][0] == o["issuer"][0] in B.BATTALIONS for o in b.mission_orders)
    other = B.build(small=False, seed=8)
    assert other.battalions[1].sim.drawn != b.battalions[1].sim.drawn


def test_generated_small_brigade_loads_and_is_a_mesh_of_40_or_more(small_sc):
    sc = small_sc
    assert sc.name == "brigade-small" and sc.duration_s == B.SMALL_DURATION
    units = suo.mesh_units(sc)
    assert len(units) >= 40
    assert {"BDE", "1BN", "2BN", "3BN", "CAV", "FA", "SPT", "1A", "3C3"} <= set(units)
    assert not [u for u in units if sc.taskorg.units[u].kind == "squad"]
    assert suo.default_eas(sc)[:4] == ["BDE", "1BN", "2BN", "3BN"]
    meta = json.loads((sc.root / "scenario.json").read_text())
    assert meta["generator"] == {"seed": 7, "small": True, "brigade": True}


def test_battalion_mesh_units_unchanged():
    plan = json.loads((BATTALION / "plan.json").read_text())
    above_squad = sorted(u["id"] for u in plan["task_organization"] if u["echelon"] != "squad")
    assert suo.mesh_units(S.load(BATTALION, events=False)) == above_squad
    assert "BN" in above_squad and len(above_squad) == 15


def test_deterministic_by_seed(made, tmp_path):
    again = tmp_path / "again"
    suo.generate(again, seed=7, small=True, brigade=True)
    for f in FILES:
        assert (again / f).read_bytes() == (made / f).read_bytes(), f
    other = tmp_path / "other"
    suo.generate(other, seed=8, small=True, brigade=True)
    assert (other / "events.jsonl.gz").read_bytes() != (made / "events.jsonl.gz").read_bytes()


def test_default_eas_meet_the_ground_truth(small_sc):
    res = evaluate(small_sc)
    assert res["incidents"] >= 30
    assert res["recall"] == 1.0, res["missed"]
    assert res["unwanted_share"] == 0.0, res["unwanted_alerts"]
    assert res["unwanted_flash"] == 0 and res["wrong_priority"] == 0
    truth = small_sc.truth()
    owners = {i["owner"] for i in truth["incidents"]}
    assert {"BDE", "1BN", "2BN", "3BN"} <= owners
    assert max(i["t0"] for i in truth["incidents"]) <= small_sc.duration_s


def test_ensure_keeps_a_fresh_scenario(made):
    before = {f: os.stat(made / f).st_mtime_ns for f in (*FILES, ondemand.STAMP)}
    assert ondemand.ensure("brigade-small", made.parent) == made
    assert {f: os.stat(made / f).st_mtime_ns for f in before} == before


def test_ensure_regenerates_when_absent_or_stale(tmp_path, monkeypatch):
    calls = []

    def fake(out: Path, args: dict) -> dict:   # stands in for the real (slower) generator
        calls.append(args)
        out.mkdir(parents=True)
        (out / "scenario.json").write_text(json.dumps({"n": len(calls)}))
        return {}
    monkeypatch.setattr(ondemand, "_generate", fake)
    p = ondemand.ensure("brigade", tmp_path)
    assert p == tmp_path / "brigade" and calls == [ondemand.VARIANTS["brigade"]]
    ondemand.ensure("brigade", tmp_path)
    assert len(calls) == 1
    stamp = json.loads((p / ondemand.STAMP).read_text())
    assert stamp["args"] == {"brigade": True, "small": False, "seed": 7}
    stamp["source_sha256"] = "0" * 64   # as if the generator's sources had changed since
    (p / ondemand.STAMP).write_text(json.dumps(stamp))
    ondemand.ensure("brigade", tmp_path)
    assert len(calls) == 2 and json.loads((p / "scenario.json").read_text()) == {"n": 2}
    assert ondemand.is_fresh(p, "brigade")
    (p / ondemand.STAMP).unlink()
    ondemand.ensure("brigade", tmp_path)
    assert len(calls) == 3
    assert not [x for x in tmp_path.iterdir() if x.name.startswith(".brigade.tmp")]


def test_source_hash_covers_the_generator_and_oracle():
    names = {p.name for p in ondemand.SOURCES}
    assert {"generator.py", "random_battle.py", "brigade.py", "threats.py"} <= names
    assert len(ondemand.source_hash()) == 64


def test_bad_requests_are_named(tmp_path):
    with pytest.raises(ValueError, match="no on-demand scenario 'division'"):
        ondemand.ensure("division", tmp_path)
    with pytest.raises(ValueError, match="--sensors"):
        suo.generate(tmp_path / "x", brigade=True, sensors=True)
    with pytest.raises(ScenarioError):
        S.load(tmp_path)   # nothing there
