"""New opportunities (Fig. 1, issue 53): an objective left clear by a withdrawing enemy before
it is taken, and the enemy expected in an engagement area withdrawing from it. On the random
battle of seed 15 (small, true tracks: quick), which draws both (H31 on OBJ-B, H32 in EA-A),
and on edits of it where the enemy stays, or comes towards our units."""
from __future__ import annotations

import json

import pytest

from ea_agent.domains.suo import generator as G
from ea_agent.domains.suo.detect import CATEGORY
from ea_agent.domains.suo.battle_plan import DURATION
from ea_agent.domains.suo.sim import Hostile
from saim_mesh import scenario as S
from saim_mesh.inprocess.evaluate import score
from benchmarks.evaluate_seeds import by_type_summary
from saim_mesh.inprocess.runner import run

SEED = 15
OWNERS = ["A", "A2", "B"]
OPP = ("objective-clear", "enemy-withdrawn")


def _battle(tmp_path, monkeypatch, edit=None):
    """Seed 15's battle, `edit` applied to its true state before anything is written."""
    build = G.build_sim

    def edited(*a, **k):
        sim = build(*a, **k)
        if edit is not None:
            edit(sim)
        return sim
    monkeypatch.setattr(G, "build_sim", edited)
    d = tmp_path / "sc"
    G.write(d, small=True, seed=SEED, incidents="random")
    truth = json.loads((d / "truth.json").read_text())
    truth["owners"] = OWNERS
    truth["incidents"] = [i for i in truth["incidents"] if i["owner"] in OWNERS]
    truth["situations"] = [s for s in truth["situations"] if s["owner"] in OWNERS]
    alerts = [a for ea in run(S.load(d), OWNERS) for a in ea.alerts]
    return truth, alerts


def _stays(sim):
    """H31 holds OBJ-B to the end: nothing clears."""
    h = sim.hostiles["H31"]
    sim.hostiles["H31"] = Hostile("H31", [h.appear, DURATION], [h.xs[0]] * 2, [h.ys[0]] * 2, h.strength, h.appear)


def _south(sim):
    """H31 leaves OBJ-B southwards, at B CO coming up: no opportunity."""
    h = sim.hostiles["H31"]
    sim.hostiles["H31"] = Hostile("H31", [h.ts[1], h.ts[1] + 400], [h.xs[0]] * 2, [h.ys[0], h.ys[0] - 1800],
                                  h.strength, h.appear, h.ts[1] + 460)


@pytest.fixture(scope="module")
def mp():
    with pytest.MonkeyPatch.context() as m:
        yield m


@pytest.fixture(scope="module")
def drawn(tmp_path_factory, mp):
    return _battle(tmp_path_factory.mktemp("opp"), mp)


def test_the_category_holds_both_types():
    assert {CATEGORY[t] for t in OPP} == {"new-opportunity"}


def test_oracle_marks_the_objective_cleared_before_the_attack(drawn):
    truth, _ = drawn
    inc = [i for i in truth["incidents"] if i["type"] == "objective-clear"]
    assert [i["owner"] for i in inc] == ["B"]   # B CO's objective: A CO has no part in it
    b = inc[0]
    assert b["about"] == ["OBJ-B"] and {"H31", "B1", "B2", "B3"} <= set(b["subjects"]) and not b["life"]
    assert b["at"] < 3600   # before B CO's attack ends: the opportunity is to take it sooner
    ew = [i for i in truth["incidents"] if i["type"] == "enemy-withdrawn"]
    assert sorted((i["owner"], i["about"][0]) for i in ew) == [("A", "EA-A"), ("A2", "EA-A")]


def test_detector_tells_it_once_per_owner_in_its_window(drawn):
    truth, alerts = drawn
    for i in [i for i in truth["incidents"] if i["type"] in OPP]:
        hits = [a for a in alerts if a.owner == i["owner"] and a.type == i["type"]]
        assert len(hits) == 1, (i, hits)
        a = hits[0]
        assert i["t0"] <= a.t <= i["t1"] and a.category == "new-opportunity"
        assert a.priority == "priority" and i["about"][0] in a.details["places"]
    # the objective's clearing, told to B CO before it took OBJ-B
    b = next(a for a in alerts if a.owner == "B" and a.type == "objective-clear")
    assert {"B1", "B2", "B3"} <= set(b.subjects) and "OBJ-B" in b.message and b.t < 3600


def test_evaluate_scores_it(drawn):
    truth, alerts = drawn
    res = score(alerts, truth)
    for typ in OPP:
        b = res["per_type"][typ]
        assert b["incidents"] >= 1 and b["missed"] == 0 and b["alerts"] == b["incidents"] and b["unwanted"] == 0
    summary = by_type_summary([{"per_type": res["per_type"]}])
    opp = summary["new-opportunity"]
    assert opp["types"] == sorted(OPP) and opp["recall"] == 1.0 and opp["unwanted_share"] == 0.0
    assert opp["incidents"] == sum(res["per_type"][t]["incidents"] for t in OPP)
    # an opportunity missed and one told with no incident are counted against it
    rows = [{"per_type": {"objective-clear": {"incidents": 2, "missed": 1, "alerts": 4, "unwanted": 1}}}]
    b = by_type_summary(rows)["objective-clear"]
    assert (b["recall"], b["unwanted_share"]) == (0.5, 0.25)


def test_silent_while_the_enemy_holds_the_objective(tmp_path, monkeypatch):
    truth, alerts = _battle(tmp_path, monkeypatch, _stays)
    assert not [i for i in truth["incidents"] if i["type"] == "objective-clear"]
    assert not [a for a in alerts if a.type == "objective-clear"]


def test_no_opportunity_when_the_enemy_comes_towards_us(tmp_path, monkeypatch):
    truth, alerts = _battle(tmp_path, monkeypatch, _south)
    assert not [i for i in truth["incidents"] if i["type"] == "objective-clear"]
    assert not [a for a in alerts if a.type == "objective-clear"]
