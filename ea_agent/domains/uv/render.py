"""Alert categories (Fig. 1), alert text, merging and the Alert form of a candidate."""
from __future__ import annotations

from ea_agent.core.alert import Alert, Candidate, highest

CATEGORY = {
    "at-goal": "reporting-requirement",
    "stuck": "system-problem",
    "divergent": "plan-constraint-violated",
    "no-status": "system-problem",
    "target-visible": "adversarial-activity",
    "lost-target": "plan-constraint-violated",
    "target-gone": "plan-constraint-violated",
    "collision": "constraint-violation-projected",
    "handoff": "reporting-requirement",
    "schedule": "plan-constraint-violated",   # start/end/photo time constraints (core Schedule)
}
ALERT_TYPES = tuple(k for k in CATEGORY if k != "schedule")   # the nine of paper 7.4


def m_(d: float) -> str:
    return f"{d:.1f} m" if d < 100 else f"{d:.0f} m"


def merge(key, cands: list[Candidate]) -> Candidate:
    """Several issued alerts sharing a merge group become one (UV detectors set no
    merge group today; kept so `[voa] merge = true` is safe)."""
    subjects = tuple(sorted({s for c in cands for s in c.subjects}))
    return Candidate(cands[0].t, cands[0].type, highest(c.priority for c in cands), subjects,
                     "; ".join(c.message for c in cands), key=key,
                     details={"merged": [{"type": c.type, "subjects": list(c.subjects), "message": c.message,
                                          "details": c.details} for c in cands]})


def to_alert(c: Candidate, owner: str, audience: str) -> Alert:
    det = dict(c.details)
    det["repeat"] = c.repeat
    det["audience"] = audience
    return Alert(round(c.t, 3), owner, c.type, CATEGORY[c.type], c.priority, tuple(c.subjects), c.message, det)
