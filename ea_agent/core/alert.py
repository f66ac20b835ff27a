"""Alert candidates (before VOA), priorities and the Fig. 1 alert ontology."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Hashable

from .messages import MessageError, need, text, time_of, register

PRIORITIES = ("flash", "immediate", "priority", "routine")  # highest first

# Fig. 1: top-level alert categories.
CATEGORIES = (
    "plan-constraint-violated", "constraint-violation-projected", "policy-constraint-violated",
    "new-opportunity", "adversarial-activity", "contingency-plan-suggested",
    "system-problem", "reporting-requirement",
)


def hms(t: float) -> str:
    """Scenario time as H+hh:mm:ss, the way alerts and messages show it. Total: an
    order's bound is +inf once every source ended and -inf before any spoke, and a text
    that names one must not kill the process that writes it."""
    if not math.isfinite(t):
        return "the end" if t > 0 else "the start" if t < 0 else "an unknown time"
    t = int(round(t))
    return f"H+{t // 3600:02d}:{t % 3600 // 60:02d}:{t % 60:02d}"


def rank(priority: str) -> int:
    return PRIORITIES.index(priority)


def lower(priority: str, steps: int = 1) -> str:
    return PRIORITIES[min(len(PRIORITIES) - 1, rank(priority) + steps)]


def highest(priorities) -> str:
    return min(priorities, key=rank)


@dataclass(slots=True)
class Candidate:
    """A possible alert produced by a detector or a mission method.

    `key` names the alert history it is judged against (e.g. ("unit", "A2")), and
    `measure` how bad it is (bigger is worse); VOA decides whether it is issued.
    """
    t: float
    type: str
    priority: str
    subjects: tuple[str, ...]
    message: str
    key: Hashable
    measure: float | None = None
    details: dict[str, Any] = field(default_factory=dict)
    merge_group: Hashable | None = None  # candidates sharing it may be merged for a common parent
    friendly: bool = True               # friendly (120 s) or hostile (90 s) suppression
    repeat: bool = False                 # set by VOA when this is a progressive repeat
    also: tuple = ()                     # ((key, measure), ...) histories this alert also updates
    projection: bool = False             # a projected violation: `also` names the actual alert's key
    news: bool = False                   # about subjects never told on this key: given whatever its history
    count: int | None = None             # hostile entities it counts (more than last told, in new tracks: news)



@dataclass(slots=True, frozen=True)
class Alert:
    """An alert as shown to a commander and sent on the mesh."""
    KIND: ClassVar[str] = "alert"
    KEY: ClassVar[str] = "alert/{owner}/{type}"
    t: float
    owner: str
    type: str
    category: str
    priority: str
    subjects: tuple[str, ...]
    message: str
    details: dict = field(default_factory=dict)

    @classmethod
    def from_dict(cls, d: dict) -> "Alert":
        k = cls.KIND
        subjects = need(d, k, "subjects")
        if not isinstance(subjects, (list, tuple)) or not all(isinstance(s, str) for s in subjects):
            raise MessageError(k, "subjects", "expected a list of strings")
        details = need(d, k, "details", {})
        if not isinstance(details, dict):
            raise MessageError(k, "details", "expected a mapping")
        return cls(time_of(d, k), text(d, k, "owner"), text(d, k, "type"), text(d, k, "category"),
                   text(d, k, "priority", PRIORITIES), tuple(subjects), text(d, k, "message"), details)

    def to_json_dict(self) -> dict:
        return {"t": self.t, "owner": self.owner, "type": self.type, "category": self.category,
                "priority": self.priority, "subjects": list(self.subjects),
                "message": self.message, "details": self.details}


register(Alert)
