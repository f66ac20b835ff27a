"""The soak's judges (benchmarks/soak.py) on crafted alert logs: a lost alert, one shown
twice, one extra, a late one (equal, counted late), one inhibited by a lost source (left
out), system problems (left out); the RSS growth of a process's last run only. The real
soak of the live mesh is `scripts/soak` (bench/results/soak.json), too long for the suite."""
from __future__ import annotations

from benchmarks.soak import growth_mb, judge, lost_declared, plan_key


def alert(t: float, id_: str, cat: str = "plan", **details) -> dict:
    return {"t": t, "type": "late", "subjects": ["A1"], "message": f"m{id_}", "priority": "high",
            "category": cat, "owner": "A", "details": {"id": id_, **details}}


def test_equal_with_late_inhibited_and_system_problems_apart():
    want = {"A": [plan_key(alert(10, "a")), plan_key(alert(20, "b"))]}
    got = {"A": [alert(10, "a"), alert(5, "s", "system-problem", event="source-lost", declared_wall=100.0),
                 alert(15, "x", inhibited_by="A/s"), alert(20, "b", late=True, due=20)]}
    v = judge(want, got)
    assert v == {"alerts_lost": 0, "alerts_extra": 0, "duplicates": 0, "late_alerts": {"A": 1},
                 "inhibited_during_loss": 1, "alerts_equal_fault_free": True, "unequal_peers": []}


def test_lost_extra_and_duplicates_are_counted():
    want = {"A": [plan_key(alert(10, "a")), plan_key(alert(20, "b"))], "B": [plan_key(alert(1, "c"))]}
    got = {"A": [alert(10, "a"), alert(10, "a"), alert(30, "z")], "B": []}
    v = judge(want, got)
    assert (v["alerts_lost"], v["alerts_extra"], v["duplicates"]) == (2, 1, 1)
    assert v["unequal_peers"] == ["A", "B"] and not v["alerts_equal_fault_free"]


def test_an_alert_that_says_something_else_is_not_equal():
    want = {"A": [plan_key(alert(10, "a"))]}
    other = alert(10, "a")
    other["priority"] = "low"
    assert judge(want, {"A": [other]})["unequal_peers"] == ["A"]


def test_lost_declared_names_the_source():
    got = {"A": [alert(5, "s", "system-problem", event="source-lost", declared_wall=100.0)],
           "B": [alert(6, "s", "system-problem", event="source-lost", declared_wall=101.0)]}
    got["A"][0]["subjects"] = ["cp.C"]
    got["B"][0]["subjects"] = ["cp.B"]
    assert lost_declared(got, "cp.C") == {"A": 100.0}


def test_rss_growth_of_the_last_run_in_the_second_half():
    mb = 1024
    restart = [(t, 1, 100 * mb) for t in range(0, 50)] + [(t, 2, (20 + (t - 50)) * mb) for t in range(50, 100)]
    assert growth_mb(restart, 50) == 45.0   # the restarted run grew one MB a second
    flat = [(t, 1, 100 * mb) for t in range(0, 50)] + [(t, 2, 20 * mb) for t in range(50, 100)]
    assert growth_mb(flat, 50) == 0.0       # a restart's smaller start is not growth
    assert growth_mb([(t, 1, mb) for t in range(60, 65)], 50) is None   # too few samples to say
