"""The score is honest: the oracle is a specification apart from the EAs, each seed is a
different battle, and an alert at the wrong priority counts against the EAs."""
import ast

import pytest

from ea_agent.core.alert import Alert
from ea_agent.domains.suo import oracle
from ea_agent.domains.suo.generator import build_sim, overlay_features, plan_doc
from saim_mesh.inprocess.evaluate import score

from .conftest import ROOT


def test_the_oracle_imports_nothing_from_ea_agent():
    """The oracle package: its parts import one another (one level up is the package itself)
    and nothing else of ea_agent."""
    files = sorted((ROOT / "ea_agent" / "domains" / "suo" / "oracle").glob("*.py"))
    assert {f.name for f in files} >= {"__init__.py", "spec.py", "base.py"}
    for f in files:
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):
                assert node.level in (0, 1) and not (node.module or "").startswith("ea_agent"), (f.name, ast.dump(node))
            elif isinstance(node, ast.Import):
                assert not any(a.name.startswith("ea_agent") for a in node.names), (f.name, ast.dump(node))


def _truth(seed: int) -> dict:
    sim = build_sim(small=True, seed=seed, incidents="random")
    return sim, oracle.ground_truth(sim, overlay_features(), plan_doc(sim), ["BN", "A", "B", "C", "A2"])


def test_each_seed_is_a_different_battle_and_the_same_seed_the_same():
    a, b = build_sim(True, 1, "random"), build_sim(True, 1, "random")
    assert a.drawn == b.drawn and a.drawn
    (s1, t1), (s2, t2) = _truth(1), _truth(2)
    assert s1.drawn != s2.drawn and s1.reorg_t != s2.reorg_t
    assert sorted(s1.hostiles) != sorted(s2.hostiles) or [h.ts for h in s1.hostiles.values()] != [
        h.ts for h in s2.hostiles.values()]
    labels = lambda t: sorted((i["owner"], i["type"], i["label"]) for i in t["incidents"])  # noqa: E731
    assert labels(t1) != labels(t2)
    for t in (t1, t2):   # a battle that shows something: contact, and every incident labelled with when
        assert {"contact"} <= {i["type"] for i in t["incidents"]}
        assert all(i["t0"] <= i["at"] + 1e-6 and "life" in i for i in t["incidents"])
    reorg = [m for m in plan_doc(s1)["plans"]["main"] if m["type"] == "reorganize"]
    assert reorg and reorg[0]["start"]["t"] == s1.reorg_t   # the reorganization is drawn too


def test_a_bad_generator_parameter_is_a_clear_error():
    with pytest.raises(ValueError, match="bogus"):
        build_sim(True, 1, "bogus")


def test_an_alert_at_the_wrong_priority_is_unwanted():
    """Flash is for what threatens lives (first contact, fratricide, fire near friendlies):
    a flash alert about a late start is unwanted, and so is a routine first alert of contact."""
    late = {"owner": "A", "type": "schedule", "accept": ["schedule"], "subjects": ["A2"], "t0": 0.0, "t1": 100.0,
            "at": 10.0, "life": False, "label": "late"}
    contact = {"owner": "A", "type": "contact", "accept": ["contact", "distance"], "subjects": ["A1", "H1"],
               "t0": 0.0, "t1": 100.0, "at": 20.0, "life": True, "label": "contact"}
    truth = {"incidents": [late, contact], "situations": []}

    def al(t, typ, pri, subj):
        return Alert(t, "A", typ, "x", pri, subj, "m", {})
    good = score([al(12, "schedule", "immediate", ("A2",)), al(25, "contact", "flash", ("A1", "H1"))], truth)
    assert good["unwanted"] == 0 and good["wrong_priority"] == 0 and good["recall"] == 1.0
    assert good["delay_s_median"] is not None and good["delay_s_p95"] == 5.0   # 2 s and 5 s after it happened
    bad = score([al(12, "schedule", "flash", ("A2",)), al(25, "contact", "routine", ("A1", "H1"))], truth)
    assert bad["wrong_priority"] == 2 and bad["unwanted_flash"] == 1 and bad["recall"] == 1.0
