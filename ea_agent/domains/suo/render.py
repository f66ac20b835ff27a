"""How SUO alerts read: distances in text, merged alerts for a common parent (a
VOA heuristic) and the final Alert. Detectors write their own candidate text;
what is here is shared by all of them or applies after VOA."""
from __future__ import annotations

from typing import Callable, Hashable

from ea_agent.core.alert import Alert, Candidate, highest


def km(d: float) -> str:
    return f"{d:.0f} m" if d < 1000 else f"{d / 1000:.1f} km"


def merge(key: Hashable, cands: list[Candidate], name: Callable[[str], str]) -> Candidate:
    """One alert for a parent from its subordinates' candidates of one merge group:
    ("unknown", parent) for silent units, ("prox", parent) for threat envelopes."""
    parent = key[1]
    subjects = tuple(sorted({s for c in cands for s in c.subjects}))
    if key[0] == "unknown":
        units = [c.subjects[0] for c in cands]
        text = f"Unknown position: {len(units)} units of {name(parent)} silent ({', '.join(name(u) for u in units)})"
        typ = "unknown-position"
    else:
        typ = "proximity"
        text = f"Threats near {name(parent)}: " + "; ".join(c.message for c in cands)
    return Candidate(cands[0].t, typ, highest(c.priority for c in cands), subjects, text, key=key,
                     details={"parent": parent, "merged": [{"type": c.type, "subjects": list(c.subjects),
                                                            "message": c.message, "details": c.details}
                                                           for c in cands]})


def to_alert(c: Candidate, owner: str, category: dict[str, str]) -> Alert:
    det = dict(c.details)
    det["repeat"] = c.repeat
    return Alert(round(c.t, 3), owner, c.type, category[c.type], c.priority, tuple(c.subjects), c.message, det)
