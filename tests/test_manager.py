"""EA manager and watchman: bad input, batching, plan switching, resubordination, determinism."""
import io
import math

import numpy as np
import pytest

from ea_agent.domains.suo import make_ea
from ea_agent.domains.suo.detect.fratricide import fratricide_pairs
from saim_mesh.protocol.messages import LocationReport, MissionConfirm, Order, Reorganization
from saim_mesh.inprocess.runner import run
from saim_mesh.logs.sinks import JsonlSink


def test_bad_input_is_counted_and_never_fatal(small):
    ea = make_ea(small, "A")
    ea.start()
    ea.submit(LocationReport(1.0, "NOBODY", -116.6, 35.2))
    ea.submit(LocationReport(2.0, "A1S1E01", -116.6, math.nan))
    ea.submit(MissionConfirm(3.0, "no-such-mission", "A1", "start"))
    ea.submit(LocationReport(4.0, "A1S1E01", -116.6, 35.21))
    ea.finish(10.0)
    assert ea.stats["errors"] == 3
    assert "NOBODY" in ea.errors[0] and "lat" in ea.errors[1] and "no-such-mission" in ea.errors[2]
    assert not np.isnan(ea.domain.pic.xy[ea.domain.pic.eidx["A1S1E01"]]).any()


def test_unknown_owner_is_a_clear_error(small):
    with pytest.raises(KeyError, match="Z9"):
        make_ea(small, "Z9")


def test_watchman_filters_unchanged_and_far_foreign_reports(small_run):
    stats = small_run["A2"].domain.watchman.stats
    assert stats["unchanged"] > 0 and stats["irrelevant"] > 0 and stats["passed"] > 0
    bn = small_run["BN"].domain.watchman.stats
    assert bn["irrelevant"] == 0          # the battalion owns every unit


def _alerts(sc, owners, **over):
    buf = io.StringIO()
    run(sc, owners, [JsonlSink(buf)], overrides=over or None)
    return buf.getvalue()


def test_replay_is_byte_identical(small):
    a = _alerts(small, ["BN", "A2"])
    assert a and a == _alerts(small, ["BN", "A2"])


def test_results_do_not_depend_on_fact_batch_size(small):
    assert _alerts(small, ["A"], manager={"fact_batch": 1}) == _alerts(small, ["A"], manager={"fact_batch": 500})


def test_abort_and_switch_plan(small):
    ea = make_ea(small, "A")
    ea.start()
    assert ea.domain.plan.plan.name == "main" and ea.timers.pending() > 0
    ea.submit(Order(50.0, "execute-plan", "withdrawal", "BN"))
    ea.advance(60.0)
    assert ea.domain.plan.plan.name == "withdrawal"
    assert set(ea.domain.missions) == {f"{p}-withdraw" for p in ("A1", "A2", "A3", "B1", "B2", "B3", "C1", "C2", "C3")}
    assert ea.timers.pending() == 0      # no monitor of the old plan survives
    ea.submit(Order(70.0, "abort-plan", "withdrawal", "BN"))
    ea.finish(100.0)
    assert ea.domain.plan is None and not [a for a in ea.alerts if a.type == "schedule" and a.t > 50]


def test_resubordination_by_message_and_by_plan(small):
    b = make_ea(small, "B")
    b.start()
    assert "R" not in b.domain.own_units
    b.submit(Reorganization(100.0, "R", "B"))
    b.advance(101.0)
    assert "R" in b.domain.own_units and "R" in b.domain.env_units
    a = make_ea(small, "A")
    a.start()
    assert "R" in a.domain.own_units
    a.finish(700.0)       # the plan's reorganize mission moves R to the battalion at 600
    assert "R" not in a.domain.own_units


def test_local_and_message_confirmations_are_the_same(small):
    out = []
    for src in ("message", "local"):
        ea = make_ea(small, "B")
        ea.start()
        ea.submit(MissionConfirm(480.0, "B3-move", "B3", "start", src))
        ea.finish(500.0)
        out.append([(a.t, a.type, a.subjects) for a in ea.alerts if a.type == "schedule"])
        assert ea.domain.plan.state["B3-move"] == "active"
    assert out[0] == out[1] and out[0]


def _frat(pos, bnd, inside, rng=1000.0):
    n = len(pos)
    return fratricide_pairs(np.array(pos, float), np.array(bnd), np.array(inside, bool), np.full(n, rng),
                            np.ones(n, bool), np.ones(n, bool))


def test_fratricide_rule_cases():
    # both inside their own boundaries, 300 m apart: no risk
    assert _frat([(0, 0), (300, 0)], [0, 1], [[1, 0], [0, 1]]) == []
    # unit 0 inside unit 1's boundary, within range: risk
    assert [p[:2] for p in _frat([(0, 0), (300, 0)], [0, 1], [[0, 1], [0, 1]])] == [(0, 1)]
    # both outside their own boundaries and within range: risk
    assert [p[:2] for p in _frat([(0, 0), (300, 0)], [0, 1], [[0, 0], [0, 0]])] == [(0, 1)]
    # out of weapons range: no risk
    assert _frat([(0, 0), (3000, 0)], [0, 1], [[0, 1], [0, 1]]) == []
    # same boundary owner: not paired
    assert _frat([(0, 0), (300, 0)], [0, 0], [[0], [0]]) == []
    # unit 0 strays but into no one's area, unit 1 at home: no risk by boundaries
    assert _frat([(0, 0), (300, 0)], [0, 1], [[0, 0], [0, 1]]) == []
