"""bench_mesh's live phase: the pieces that decide what is compared and counted (no mesh
started here, no timing asserted)."""
from __future__ import annotations

import json
from collections import Counter

from saim_mesh.protocol import messages as M
from benchmarks.mesh import (alerts_diff, in_process_same_input, logged_alerts, merge_live, peer_inputs,
                                  source_streams)
from saim_mesh.live.depend import cp_shares
from saim_mesh.inprocess.runner import config_for, make_ea


def _alert(t, category="plan-constraint-violated", **kw):
    return {"t": t, "owner": "A", "type": kw.get("type", "schedule"), "category": category, "priority": "priority",
            "subjects": ["A1"], "message": f"at {t}", "details": {"id": "A/1"}}


def test_logged_alerts_leave_out_system_problems_and_a_cut_line(tmp_path):
    p = tmp_path / "A.jsonl"
    lines = [json.dumps(_alert(10.0)), json.dumps(_alert(12.0, "system-problem")), json.dumps(_alert(14.0))]
    p.write_text("\n".join(lines) + "\n" + json.dumps(_alert(16.0))[:20])   # the last one cut by a kill
    assert logged_alerts(p) == [(10.0, "A", "schedule", "priority", ("A1",), "at 10.0"),
                                (14.0, "A", "schedule", "priority", ("A1",), "at 14.0")]


def test_alerts_diff():
    a, b, c = (1.0, "A", "x", "p", (), "m"), (2.0, "A", "x", "p", (), "m"), (3.0, "A", "x", "p", (), "m")
    assert alerts_diff([a, b], [a, b]) is None
    assert alerts_diff([b, a], [a, b]) == {"peer": 2, "in_process": 2, "only_peer": 0, "only_in_process": 0,
                                           "order_only": True}
    assert alerts_diff([a, c, c], [a, b]) == {"peer": 3, "in_process": 2, "only_peer": 2, "only_in_process": 1,
                                              "order_only": False}


def test_merge_live_keeps_the_other_phases(tmp_path):
    p = tmp_path / "mesh.json"
    p.write_text(json.dumps({"raw_msgs_per_s": 1, "ea_cpu_us_per_event": 99, "targets": {"latency_p99_ms": 20}}))
    out = merge_live(p, {"live": {}, "ea_cpu_us_per_event": 20.0, "in_process_cpu_us_per_event": 10.0})
    assert out["raw_msgs_per_s"] == 1 and out["ea_cpu_us_per_event"] == 20.0
    assert out["in_process_cpu_us_per_event"] == 10.0
    assert out["targets"]["latency_p99_ms"] == 20 and out["targets"]["ea_cpu_ratio"] == 1.5
    assert merge_live(tmp_path / "none.json", {"live": {}})["live"] == {}


def test_sources_carry_each_event_once(small):
    """The command posts' shares split the scenario: every event in exactly one source."""
    streams = source_streams(small)
    assert set(streams) == set(cp_shares(small))
    sent = Counter(id(m) for ms in streams.values() for m in ms)
    assert max(sent.values()) == 1
    assert len(sent) == sum(type(e) is not M.SensorHit for e in small.events)


def test_in_process_same_input_is_what_the_peer_gets(small):
    streams = source_streams(small)
    ea = make_ea(small, "A2", config_for(small, "A2", None), sinks=[])
    ea.start(0.0)
    msgs = peer_inputs(small, ea, streams)
    assert [m.t for m in msgs] == sorted(m.t for m in msgs)
    got = in_process_same_input(small, ["A2"], streams)["A2"]
    assert got["messages"] == len(msgs) > 0
    assert all(a[1] == "A2" for a in got["alerts"])


def test_beside_ratio_compares_the_units_it_finished_only(small):
    """The same-moment baseline: peers' CPU per message over the units the thread finished,
    against the thread's own; a unit it did not finish, or a peer with no messages, is left
    out; nothing finished gives no ratio rather than a made-up one."""
    from benchmarks.beside import InProcessBeside
    b = InProcessBeside(small, ["A1", "A2"], {})
    assert b.ratio({"A1": {"messages": 100, "thread_cpu_s": 0.003}})["ea_cpu_ratio_same_time"] is None
    b.done = {"A1": [0.001, 100], "A2": [0.002, 100]}
    peers = {"A1": {"messages": 100, "thread_cpu_s": 0.003}, "A2": {"messages": 0, "thread_cpu_s": 0.5},
             "BN": {"messages": 100, "thread_cpu_s": 9.0}}
    r = b.ratio(peers)
    assert r["same_time_units"] == ["A1"]
    assert r["in_process_same_time_cpu_us_per_event"] == 10.0 and r["ea_cpu_us_per_event_same_units"] == 30.0
    assert r["ea_cpu_ratio_same_time"] == 3.0


def test_beside_stopped_before_it_ran_counts_nothing(small):
    from benchmarks.beside import InProcessBeside
    b = InProcessBeside(small, ["A2"], {})
    b._halt.set()
    b.run()   # on this thread: returns at once
    assert b.done == {}


def test_best_of_rounds_takes_each_sides_least_cpu_and_equal_only_when_every_round_was():
    from benchmarks.mesh import best_of

    def rnd(ea, ip, eq, pss):
        return {"ea_cpu_us_per_event": ea, "in_process_cpu_us_per_event": ip, "ea_cpu_ratio": round(ea / ip, 3),
                "ea_cpu_ratio_same_time": ea / ip - 0.1, "ea_cpu_us_per_event_after_setup": ea - 1,
                "ea_cpu_ratio_after_setup": (ea - 1) / ip, "live_all_equal": eq, "live_pss_mb_max": pss,
                "journal_replay_cpu_us_per_event": ip + 1.5, "wall_s": 20.0}
    out = best_of([rnd(20.0, 12.0, True, 30.0), rnd(17.0, 13.0, True, 31.0), rnd(19.0, 11.5, False, 29.0)])
    assert out["ea_cpu_us_per_event"] == 17.0 and out["in_process_cpu_us_per_event"] == 11.5
    assert out["ea_cpu_ratio"] == round(17.0 / 11.5, 3)
    assert out["ea_cpu_ratio_after_setup"] == round(16.0 / 11.5, 3)
    assert out["live_all_equal"] is False
    assert out["cpu_split_us_per_event"] == {"ea": 11.5, "decode_gate_order": 1.5, "live_loop": 4.0}
    assert out["live_pss_mb_max"] == 31.0 and out["rounds"] == 3 and len(out["by_round"]) == 3
