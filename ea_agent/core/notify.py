"""What a commander does with alerts (docs/console.md section 1): ids, stories,
re-notification and escalation of unacknowledged urgent alerts, silences, inhibition
rules, and thresholds changed at run time.

Everything runs on scenario time and is driven by the manager's epoch closes, so a
run gives the same alerts and notices whatever the wall clock did:
 - every alert gets `details["id"]`, derived from what it says (`ids.AlertIds`: one id
   names one alert for ever, across rebuilds, restarts and late joins), and
   `details["story"]`, the id of the first alert of its story (same type and subjects,
   not expired);
 - once armed (a commander acted on this EA: a batch run stays the paper's baseline),
   a flash or immediate alert not acknowledged is *re-notified* (a `Notice`, never a new
   alert: Alertmanager's repeat_interval) every `[notify.<priority>] every_s`, at most
   `times` times, and *escalated* once to the superior's EA and console after
   `escalate_s` (PagerDuty's escalation to the next person, never a higher priority);
 - what one commander is shown of these notices is bounded by their notice budget
   (`budget.Budget`, `[notify] budget`): a proportion of the new alerts their own EA gave
   them lately; a flash alert's escalation is always given;
 - an alert matching an active silence is given marked `silenced`; one an inhibition
   rule mutes is given marked `inhibited_by`: both are logged, neither is shown as new,
   re-notified or escalated;
 - a threshold change is checked as the config file is and applied at the next epoch.
"""
from __future__ import annotations

import heapq
import logging
import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable

from .alert import Alert
from .budget import Budget
from .config import check_setting
from .ids import AlertIds
from .inhibit import Inhibitor, Rule, rule as make_rule

log = logging.getLogger(__name__)
URGENT = frozenset({"flash", "immediate"})
# Values a Voa object caches at init: dotted key -> its attribute.
VOA_ATTRS = {"voa.expiry_s": "expiry", "voa.suppress_friendly_s": "suppress_friendly",
             "voa.suppress_hostile_s": "suppress_hostile"}
RENOTIFY, ESCALATE, ACK = 0, 1, -1   # heap entry kinds (an ack due at the same time goes first)


@dataclass(slots=True, frozen=True)
class Notice:
    """A re-notification of an unacknowledged urgent alert (`renotify`, to its own EA's
    commander) or its escalation to the superior (`escalate`, `to` = the superior's unit).
    Not an alert: it never enters the alert log, the counts or VOA."""
    kind: str
    t: float
    owner: str
    alert: str          # the original alert's id
    story: str
    type: str
    priority: str       # the original's, unchanged: escalation goes up the chain, not the priorities
    subjects: tuple[str, ...]
    message: str
    count: int          # the n-th re-notification (escalate: 1)
    to: str             # the unit whose commander is told
    due_t: float        # when the original was raised

    def to_json_dict(self) -> dict:
        return {"kind": self.kind, "t": self.t, "owner": self.owner, "alert": self.alert, "story": self.story,
                "type": self.type, "priority": self.priority, "subjects": list(self.subjects),
                "message": self.message, "count": self.count, "to": self.to, "due_t": self.due_t}


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
    """An urgent alert waiting for its acknowledgement."""
    alert: Alert
    count: int = 0          # re-notifications given
    escalated: bool = False


def _names(v: Any, what: str) -> frozenset[str]:
    if not isinstance(v, (list, tuple, set, frozenset)) or not all(isinstance(x, str) and x for x in v):
        raise ValueError(f"silence: field '{what}': expected a list of non-empty strings")
    return frozenset(v)


class Notifier:
    def __init__(self, owner: str, cfg: dict, superior: Callable[[], str | None] = lambda: None):
        n = cfg.get("notify", {})
        self.owner = owner
        self.cfg = cfg
        self.superior = superior   # the unit above this EA's, as the task organization stands now
        self.cadence: dict[str, tuple[float, int]] = {
            p: (float(n.get(p, {}).get("every_s", 0.0)), int(n.get(p, {}).get("times", 0))) for p in URGENT}
        self.escalate_s = float(n.get("escalate_s", 0.0))   # 0: never escalate
        self.budget = Budget(owner, n)   # what this EA's commander may be shown of notices
        # the budget of the commander a notice goes to (the runner wires the superiors run
        # in the same process; None: not known here, the notice is given)
        self.budget_for: Callable[[str], Budget | None] = lambda u: self.budget if u == owner else None
        expiry = float(cfg.get("voa", {}).get("expiry_s", 720.0))
        self.inhibitor = Inhibitor(cfg.get("inhibit", []), expiry)
        self.story_s = expiry       # a story ends when nothing was told on it for this long
        self.armed = False
        self.ack_after_s: float | None = None   # a commander model (evaluate --commander): acks after this
        self.ids = AlertIds(owner)  # every id issued (a live peer shares its own across rebuilds)
        self.chains: dict[str, Chain] = {}
        self.due: list[tuple[float, int, int, str]] = []  # (scenario time, kind, tie, original id)
        self._tie = 0
        self.stories: dict[tuple, tuple[str, float]] = {}   # (type, subjects) -> (story id, last t)
        self.silences: dict[str, Silence] = {}
        self.pending: list[tuple[str, Any, float]] = []   # (key, checked value, requested at)
        self.changes: list[dict] = []
        self.acked: dict[str, float] = {}   # original id -> when (bounded by the urgent alerts given)

    # -- alerts --------------------------------------------------------------------
    def stamp(self, alert: Alert) -> Alert:
        """The alert with its id, story, silence or inhibition mark; watched for its
        acknowledgement when urgent and armed."""
        d = dict(alert.details)
        d["id"] = self.ids.issue(alert, wall=bool(d.get("wall_clock_driven")))
        d["story"] = self._story(alert, d["id"])
        d.pop("silenced", None)
        d.pop("inhibited_by", None)
        s = self.silence_for(alert)
        if s is not None:
            d["silenced"] = s.id
        out = replace(alert, details=d)
        if self.inhibitor.rules:
            why = self.inhibitor.judge(out)
            if why is not None:
                d["inhibited_by"] = why
        shown = "silenced" not in d and "inhibited_by" not in d
        if shown:
            self.budget.alert(alert.t)
        if self.armed and shown and alert.priority in URGENT:
            every, times = self.cadence[alert.priority]
            self.chains[d["id"]] = Chain(out)
            if every > 0 and times > 0:
                self._schedule(alert.t + every, RENOTIFY, d["id"])
            if self.escalate_s > 0:
                self._schedule(alert.t + self.escalate_s, ESCALATE, d["id"])
            if self.ack_after_s is not None:
                self._schedule(alert.t + self.ack_after_s, ACK, d["id"])
        return out

    def _story(self, a: Alert, aid: str) -> str:
        key = (a.type, tuple(sorted(a.subjects)))
        old = self.stories.get(key)
        sid = old[0] if old is not None and a.t - old[1] <= self.story_s else aid
        self.stories[key] = (sid, a.t)
        return sid

    def quiet(self, a: Alert) -> bool:
        """Silenced or inhibited: logged, never shown as new."""
        return "silenced" in a.details or "inhibited_by" in a.details

    def silence_for(self, a: Alert, t: float | None = None) -> Silence | None:
        for s in self.silences.values():
            if s.matches(a, t):
                return s
        return None

    def _schedule(self, t: float, kind: int, orig: str) -> None:
        self._tie += 1
        heapq.heappush(self.due, (t, kind, self._tie, orig))

    def next_due(self) -> float:
        """When the manager must close an epoch for a notice (inf: none)."""
        while self.due and self.due[0][3] not in self.chains:
            heapq.heappop(self.due)
        return self.due[0][0] if self.due else math.inf

    def notices_until(self, end: float) -> list[Notice]:
        """The re-notifications and escalations due by `end`, in time order."""
        out = []
        while self.due and self.due[0][0] <= end:
            t, kind, _, orig = heapq.heappop(self.due)
            ch = self.chains.get(orig)
            if ch is None:
                continue   # acknowledged meanwhile
            if kind == ACK:   # the commander model acknowledges
                self.ack(orig, t)
                continue
            a = ch.alert
            if self.silence_for(a, t) is not None:
                continue   # silenced since it was raised: the commander knows; nothing more of this kind
            if kind == RENOTIFY:
                every, times = self.cadence[a.priority]
                ch.count += 1
                if ch.count < times:
                    self._schedule(t + every, RENOTIFY, orig)
                # a flash alert's first reminder is always given (a threat to life is never left
                # said once); it is counted, so the rest give way to it
                if not self.budget.allow(t, force=a.priority == "flash" and ch.count == 1):
                    log.info("EA %s: re-notification %d of %s held back at t=%.1f (notice budget)", self.owner,
                             ch.count, orig, t)
                    continue
                out.append(self._notice("renotify", t, a, ch.count, self.owner))
            else:
                up = self.superior()
                if up is None or ch.escalated:
                    continue   # the top of the chain has nobody to escalate to
                ch.escalated = True
                b = self.budget_for(up)
                if b is not None and not b.allow(t, force=a.priority == "flash"):
                    log.info("EA %s: escalation of %s to %s held back at t=%.1f (its notice budget)", self.owner,
                             orig, up, t)
                    continue
                out.append(self._notice("escalate", t, a, 1, up))
        return out

    def _notice(self, kind: str, t: float, a: Alert, count: int, to: str) -> Notice:
        d = a.details
        return Notice(kind, round(t, 3), self.owner, d["id"], d.get("story", d["id"]), a.type, a.priority,
                      tuple(a.subjects), a.message, count, to, a.t)

    # -- commands ------------------------------------------------------------------
    def known(self, alert_id: Any) -> bool:
        """An id this EA issued."""
        return alert_id in self.ids

    def ack(self, alert_id: str, t: float) -> dict:
        if not self.known(alert_id):
            raise KeyError(f"ack: unknown alert {str(alert_id)[:80]!r}: not issued by the EA of {self.owner} "
                           f"({len(self.ids)} alerts issued so far)")
        ch = self.chains.pop(alert_id, None)
        if ch is not None:
            self.acked[alert_id] = t
            log.info("EA %s: alert %s acknowledged at t=%.1f after %d re-notifications", self.owner, alert_id, t,
                     ch.count)
        return {"alert": alert_id, "stopped": ch is not None, "renotified": ch.count if ch else 0,
                "escalated": ch.escalated if ch else False}

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

    def inhibit(self, d: dict) -> Rule:
        """A rule added at run time (the `inhibit` command), checked like a config one."""
        r = self.inhibitor.add(make_rule(d, "inhibit", self.inhibitor.default_for_s))
        log.info("EA %s: inhibition rule %s", self.owner, r.to_dict())
        return r

    def uninhibit(self, rid: str) -> Rule:
        r = self.inhibitor.remove(rid)
        log.info("EA %s: inhibition rule %s lifted", self.owner, rid)
        return r

    def forget_before(self, t: float) -> None:
        """Stories nothing was told on since `t` are over (memory stays bounded)."""
        for k in [k for k, (_, last) in self.stories.items() if last < t]:
            del self.stories[k]

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
