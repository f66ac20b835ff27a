"""The soak's judges (benchmarks/soak.py) on crafted alert logs: a lost alert, one shown
twice, one extra, a late one (equal, counted late), one inhibited by a lost source (left
out), system problems (left out); the RSS growth of a process's last run only. Then a real
soak of the live mesh, shortened: the small battle at 80x with a few kills (the full one is
`scripts/soak`, bench/results/soak.json)."""
from __future__ import annotations

import pytest

from benchmarks import ROOT
from benchmarks.soak import growth_mb, judge, lost_declared, plan_key, soak


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


@pytest.mark.timeout(240)
def test_a_short_soak_of_the_live_mesh(tmp_path):
    """The small battle at 80x through `mesh up` (secure): a few EAs and sources killed and
    restarted, cp.C kept down past its silence limit (from event time 1500, back near
    3500), company C's router link cut and healed after it (from 4000, for 960 s of event
    time), junk and forged directives; every alert raised once and equal to the fault-free
    run's. `up` stops every child it started, on failure too."""
    res = soak(str(ROOT / "scenarios" / "small"), tmp_path / "mesh", 80.0, kills=3, every_s=6.0, hold="cp.C",
               hold_at=1500.0, hold_s=None, cut="C", cut_at=4000.0, cut_s=12.0)
    assert res["restarts"] >= 3 and res["held_down"]["eas_declaring_lost"] == res["held_down"]["eas_depending"]
    assert res["rejects_by_kind"].get("directive") and res["rejects_by_kind"].get("signed"), res["rejects_by_kind"]
    assert res["attacker_error"] is None and res["given_up"] == [] and res["cut"]["healed"]
    assert (res["alerts_lost"], res["duplicates"], res["alerts_extra"]) == (0, 0, 0), res["unequal_peers"]
    assert res["alerts_equal_fault_free"]
