"""Group assembly: the first alert about a group of hostiles waits for the whole group.

A group's members are reported one track at a time, a fraction of a second apart,
and an epoch boundary can fall between them: an alert made at the first epoch would
count only the members reported before it, and the rest would be a repeat inside the
suppression interval. So a detector holds the first entity-counting alert about a
group (one naming tracks new to the area or envelope) for `voi.group_s` of event time
after its first member's report; re-offered while held, the latest candidate replaces the held one
(it counts what arrived since). It is given at the first epoch close at or after
that time, dated then. Deterministic: it depends on report times and epoch closes
only, which every EA fed the same reports shares.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Hashable, Iterable

from ea_agent.core.alert import Candidate

if TYPE_CHECKING:
    from ..domain import SuoDomain


@dataclass(slots=True)
class Held:
    due: float      # event time the group has had to assemble by
    cand: Candidate  # the latest candidate offered on its key


class Assembly:
    """First entity-counting candidates held per key until their group has assembled."""

    def __init__(self) -> None:
        self.held: dict[Hashable, Held] = {}
        self._next = math.inf

    def holds(self, key: Hashable) -> bool:
        return key in self.held

    def offer(self, c: Candidate, first_t: float, hold_s: float, first: bool) -> bool:
        """Hold `c` if it is a first alert about a group (`first`) or its key is held already;
        `first_t`: the report time of its group's first member. False: not held, give it on."""
        h = self.held.get(c.key)
        if h is None:
            if not first or hold_s <= 0.0 or c.t >= first_t + hold_s:
                return False
            self.held[c.key] = Held(first_t + hold_s, c)
            self._next = min(self._next, first_t + hold_s)
            return True
        if h.cand.news:   # news once is news still: the held alert is about a new group
            c.news = True
        was = h.cand.details.get("new_tracks")
        if was and "new_tracks" in c.details:   # the group's new members: those of every offer
            c.details["new_tracks"] = sorted({*was, *c.details["new_tracks"]})
        h.cand = c
        return True

    def due(self, t: float) -> list[Candidate]:
        """The held candidates whose group has assembled by `t` (an epoch's end), dated `t`."""
        if t < self._next:
            return []
        out = []
        for k in [k for k, h in self.held.items() if h.due <= t]:
            c = self.held.pop(k).cand
            c.t = t
            out.append(c)
        self._next = min((h.due for h in self.held.values()), default=math.inf)
        return out

    def next_due(self) -> float:
        """When the next held candidate is due (the manager closes that epoch)."""
        return self._next

    def drop_key(self, key: Hashable) -> None:
        """Forget the candidate held on `key`, if any (its group went before it assembled)."""
        if self.held.pop(key, None) is not None:
            self._next = min((h.due for h in self.held.values()), default=math.inf)

    def drop(self, gone: Callable[[Hashable], bool]) -> None:
        """Forget the held candidates whose key `gone` names (their monitor ended)."""
        for k in [k for k in self.held if gone(k)]:
            del self.held[k]
        self._next = min((h.due for h in self.held.values()), default=math.inf)


def hold_first(dom: SuoDomain, c: Candidate, members: Iterable[str], first: bool) -> bool:
    """Offer `c` to the domain's assembly, its group's first member the earliest report
    among `members` (tracks of the picture). False: give it now. With VOA off (the naive
    baseline) every candidate is given as made."""
    if not dom.ea.voa.enabled:
        return False
    tracks = dom.pic.tracks
    first_t = min((tracks[k].t for k in members if k in tracks), default=c.t)
    return dom.assembly.offer(c, first_t, float(dom.voi_cfg["group_s"]), first)
