"""A fact other than a report (a mission's confirmation, a call for fire) is judged on
the picture of the reports before it and none after, whatever the manager's batch
size: a mesh peer hears fewer messages than an in-process EA, so its batches end
elsewhere, and its alerts must still be the in-process ones (brigade 3B, 3BN)."""
from __future__ import annotations

from ea_agent.domains.suo import make_ea
from saim_mesh.protocol.messages import LocationReport, MissionConfirm
from saim_mesh.inprocess.runner import config_for


def _until_end_of(sc, mission: str) -> tuple[list, MissionConfirm]:
    evs = []
    for ev in sc.events:
        evs.append(ev)
        if type(ev) is MissionConfirm and ev.mission == mission and ev.phase == "end":
            return evs, ev
    raise AssertionError(f"no end confirmation of {mission}")


def _final_checks(sc, unit: str, evs: list, batch: int, until: float) -> list:
    cfg = config_for(sc, unit, overrides={"manager": {"fact_batch": batch}})
    ea = make_ea(sc, unit, cfg)
    ea.start()
    for ev in evs:
        ea.submit(ev)
    ea.advance(until)
    return [(a.t, a.message, a.details.get("distance_m")) for a in ea.alerts
            if a.type == "out-of-position" and a.details.get("check") == "destination"]


def test_a_confirmation_is_judged_without_the_reports_after_it(small):
    evs, end = _until_end_of(small, "A1-move")
    last = {e.entity: e for e in evs if type(e) is LocationReport and small.taskorg.entity_unit[e.entity].startswith("A1")}
    # right after the confirmation, every member of A1 reports some 3 km east of where it was
    later = [LocationReport(end.t + 0.01 * (k + 1), e, r.lon + 0.033, r.lat) for k, (e, r) in enumerate(sorted(last.items()))]
    assert len(later) >= 8
    before = _final_checks(small, "A", evs, 1, end.t + 4.0)   # one fact at a time: the reference
    assert _final_checks(small, "A", evs + later, 1, end.t + 4.0) == before
    assert _final_checks(small, "A", evs + later, 500, end.t + 4.0) == before   # all in one batch


def test_confirmations_apply_at_once(small):
    """Reports wait in the batch; a confirmation does not (the domain says which wait)."""
    ea = make_ea(small, "A", config_for(small, "A", overrides={"manager": {"fact_batch": 500}}))
    ea.start()
    ea.submit(LocationReport(1.0, "A1S1E01", -116.6, 35.2))
    assert ea.pending
    ea.submit(MissionConfirm(2.0, "A1-move", "A1", "start"))
    assert not ea.pending and ea.domain.plan.state["A1-move"] == "active"
