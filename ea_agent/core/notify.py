"""What a commander does with alerts (docs/console.md section 1): ids, acknowledgement
with repeats and escalation, silences, and thresholds changed at run time.

Everything runs on scenario time and is driven by the manager's epoch closes, so a
run gives the same alerts whatever the wall clock did:
 - every alert gets `details["id"] = "<owner>/<n>"`, n counting from 1 in emission
   order (wall-clock-driven system alerts count apart, `<owner>/w<n>`, so that a
   presence note never shifts the ids of the plan's alerts);
 - once armed (a commander acted on this EA: a batch run stays the paper's baseline),
   a flash or immediate alert not acknowledged is repeated every `repeat_s` (a new
   alert with `repeat_of` and `repeats`), raised one priority from the repeat after
   `escalate_after` on;
 - an alert matching an active silence is still given, marked `silenced`, and never
   repeated; a repeat falling inside a silence is skipped, not counted;
 - a threshold change is checked as the config file is and applied at the next epoch.
"""
from __future__ import annotations

import heapq
import logging
import math
from dataclasses import dataclass, field, replace
from typing import Any

from .alert import PRIORITIES, Alert, rank
from .config import check_setting

log = logging.getLogger(__name__)
URGENT = frozenset({"flash", "immediate"})
# Values a Voa object caches at init: dotted key -> its attribute.
VOA_ATTRS = {"voa.expiry_s": "expiry", "voa.suppress_friendly_s": "suppress_friendly",
             "voa.suppress_hostile_s": "suppress_hostile"}


def raised(priority: str) -> str:
    """One priority higher (flash stays flash)."""
    return PRIORITIES[max(0, rank(priority) - 1)]


@dataclass(slots=True)
class Silence:
    id: str
    types: frozenset[str]
    subjects: frozenset[str]
    areas: frozenset[str]
    until_t: float
    comment: str = ""
    t: float = 0.0

    def matches(self, a: Alert, t: float | None = None) -> bool:
        """Every non-empty matcher matches, before `until_t` (at `t`, default the alert's time)."""
        if (a.t if t is None else t) >= self.until_t:
            return False
        if self.types and a.type not in self.types:
            return False
        if self.subjects and self.subjects.isdisjoint(a.subjects):
            return False
        return not self.areas or not self.areas.isdisjoint(a.details.get("places", ()))


@dataclass(slots=True)
class Chain:
    """An urgent alert waiting for its acknowledgement, and the ids of its repeats."""
    alert: Alert
    repeats: int = 0
    ids: list[str] = field(default_factory=list)


def _names(v: Any, what: str) -> frozenset[str]:
    if not isinstance(v, (list, tuple, set, frozenset)) or not all(isinstance(x, str) and x for x in v):
        raise ValueError(f"silence: field '{what}': expected a list of non-empty strings")
    return frozenset(v)


class Notifier:
    def __init__(self, owner: str, cfg: dict):
        n = cfg.get("notify", {})
        self.owner = owner
        self.cfg = cfg
        self.repeat_s = float(n.get("repeat_s", 60.0))
        self.escalate_after = int(n.get("escalate_after", 2))
        if not (math.isfinite(self.repeat_s) and self.repeat_s > 0):   # a zero would repeat forever
            raise ValueError(f"notify.repeat_s must be > 0 (got {self.repeat_s})")
        self.armed = False
        self.n = 0                  # plan alerts issued (ids <owner>/1..n)
        self.nw = 0                 # wall-clock-driven alerts issued (ids <owner>/w1..wn)
        self.chains: dict[str, Chain] = {}
        self.chain_of: dict[str, str] = {}          # repeat id -> the original's id
        self.due: list[tuple[float, int, str]] = []  # (scenario time, tie, original id)
        self._tie = 0
        self.silences: dict[str, Silence] = {}
        self.pending: list[tuple[str, Any, float]] = []   # (key, checked value, requested at)
        self.changes: list[dict] = []
        self.acked: dict[str, float] = {}   # original id -> when (bounded by the urgent alerts given)

    # -- alerts --------------------------------------------------------------------
    def stamp(self, alert: Alert) -> Alert:
        """The alert with its id (and silence mark); registered for repeats when urgent."""
        d = dict(alert.details)
        if d.get("wall_clock_driven"):
            self.nw += 1
            d["id"] = f"{self.owner}/w{self.nw}"
        else:
            self.n += 1
            d["id"] = f"{self.owner}/{self.n}"
        d.pop("silenced", None)
        s = self.silence_for(alert)
        if s is not None:
            d["silenced"] = s.id
        out = replace(alert, details=d)
        if self.armed and s is None and "repeat_of" not in d and alert.priority in URGENT:
            self.chains[d["id"]] = Chain(out)
            self._schedule(alert.t + self.repeat_s, d["id"])
        return out

    def silence_for(self, a: Alert, t: float | None = None) -> Silence | None:
        for s in self.silences.values():
            if s.matches(a, t):
                return s
        return None

    def _schedule(self, t: float, orig: str) -> None:
        self._tie += 1
        heapq.heappush(self.due, (t, self._tie, orig))

    def next_due(self) -> float:
        """When the manager must close an epoch for a repeat (inf: none)."""
        while self.due and self.due[0][2] not in self.chains:
            heapq.heappop(self.due)
        return self.due[0][0] if self.due else math.inf

    def repeats_until(self, end: float) -> list[Alert]:
        """The repeats due by `end`, in time order (the manager emits them)."""
        out = []
        while self.due and self.due[0][0] <= end:
            t, _, orig = heapq.heappop(self.due)
            ch = self.chains.get(orig)
            if ch is None:
                continue   # acknowledged meanwhile
            self._schedule(t + self.repeat_s, orig)
            a = ch.alert
            if self.silence_for(a, t) is not None:
                continue   # silenced now: skipped, not counted
            ch.repeats += 1
            prio = raised(a.priority) if ch.repeats > self.escalate_after else a.priority
            d = {k: v for k, v in a.details.items() if k not in ("id", "silenced")}
            d.update(repeat_of=orig, repeats=ch.repeats)
            if prio != a.priority:
                d["escalated_from"] = a.priority
            out.append(replace(a, t=round(t, 3), priority=prio, details=d))
        return out

    def chained(self, orig: str, repeat: Alert) -> None:
        """A repeat was given its id: acknowledging it acknowledges the chain."""
        ch = self.chains.get(orig)
        if ch is not None:
            ch.ids.append(repeat.details["id"])
            self.chain_of[repeat.details["id"]] = orig

    # -- commands ------------------------------------------------------------------
    def known(self, alert_id: Any) -> bool:
        """An id this EA issued."""
        if not isinstance(alert_id, str) or "/" not in alert_id:
            return False
        owner, n = alert_id.rsplit("/", 1)
        wall = n.startswith("w")
        n = n[1:] if wall else n
        return owner == self.owner and n.isdigit() and 1 <= int(n) <= (self.nw if wall else self.n)

    def ack(self, alert_id: str, t: float) -> dict:
        if not self.known(alert_id):
            raise KeyError(f"ack: unknown alert {str(alert_id)[:80]!r}: not issued by the EA of {self.owner} "
                           f"(ids {self.owner}/1..{self.owner}/{self.n})")
        orig = self.chain_of.get(alert_id, alert_id)
        ch = self.chains.pop(orig, None)
        if ch is not None:
            for i in ch.ids:
                self.chain_of.pop(i, None)
            self.acked[orig] = t
            log.info("EA %s: alert %s acknowledged at t=%.1f after %d repeats", self.owner, orig, t, ch.repeats)
        return {"alert": alert_id, "of": orig, "stopped": ch is not None, "repeats": ch.repeats if ch else 0}

    def silence(self, sid: str, types=(), subjects=(), areas=(), until_t: float = 0.0, comment: str = "",
                t: float = 0.0) -> Silence:
        if not isinstance(sid, str) or not sid:
            raise ValueError("silence: field 'id': expected a non-empty string")
        ty, su, ar = _names(list(types), "types"), _names(list(subjects), "subjects"), _names(list(areas), "areas")
        if not (ty or su or ar):
            raise ValueError("silence: give at least one of types, subjects, areas (an empty silence would "
                             "silence everything)")
        if isinstance(until_t, bool) or not isinstance(until_t, (int, float)) or not math.isfinite(until_t):
            raise ValueError(f"silence: field 'until_t': expected a finite number, got {until_t!r:.40}")
        if until_t <= t:
            raise ValueError(f"silence: field 'until_t': {until_t} is not after the EA's time {t}")
        if not isinstance(comment, str):
            raise ValueError("silence: field 'comment': expected a string")
        s = Silence(sid, ty, su, ar, float(until_t), comment, t)
        self.silences[sid] = s
        log.info("EA %s: silence %s until t=%.1f (types %s, subjects %s, areas %s) %s", self.owner, sid, until_t,
                 sorted(ty), sorted(su), sorted(ar), comment)
        return s

    def unsilence(self, sid: str) -> Silence:
        s = self.silences.pop(sid, None) if isinstance(sid, str) else None
        if s is None:
            raise KeyError(f"unsilence: unknown silence {str(sid)[:80]!r} (active: "
                           f"{', '.join(sorted(self.silences)) or 'none'})")
        log.info("EA %s: silence %s lifted", self.owner, sid)
        return s

    def expire(self, end: float) -> None:
        for sid in [k for k, s in self.silences.items() if s.until_t <= end]:
            log.info("EA %s: silence %s expired at t=%.1f", self.owner, sid, end)
            del self.silences[sid]

    def set_param(self, key: str, value: Any, t: float) -> Any:
        """Check now (ConfigError naming the key), apply at the next epoch close."""
        v = check_setting(self.cfg, key, value)
        self.pending.append((key, v, t))
        return v

    def apply_pending(self, end: float, voa) -> list[dict]:
        done = []
        for key, v, asked in self.pending:
            parts = key.split(".")
            node = self.cfg
            for p in parts[:-1]:
                node = node[p]
            old = node[parts[-1]]
            node[parts[-1]] = v   # in place: domains hold the [voi] table itself
            if key in VOA_ATTRS:
                setattr(voa, VOA_ATTRS[key], float(v))
            elif parts[:2] == ["voa", "repeat"] and len(parts) == 3:
                voa.repeat[parts[2]] = float(v)
            elif key == "voa.merge":
                voa.merge_enabled = bool(v) and voa.merge_fn is not None
            ch = {"t": end, "key": key, "old": old, "new": v, "asked_t": asked}
            log.info("EA %s: %s = %r (was %r) from t=%.1f", self.owner, key, v, old, end)
            self.changes.append(ch)
            done.append(ch)
        self.pending = []
        return done
