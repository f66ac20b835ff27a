"""The EA manager: a reactive loop over facts on scenario time.

reports -> watchman (domain.watch) -> facts in batches (domain.apply)
        -> at each epoch end: timed monitors + detectors (domain.detect)
        -> alert candidates -> VOA (judge, merge) -> sinks

Facts are applied as they come; detection runs once per scenario-time epoch on
what changed in it. Results therefore depend only on the facts and their
timestamps, never on how they were chunked into batches or on wall-clock time.
"""
from __future__ import annotations

import logging
import math
from collections import Counter
from typing import Callable, Iterable, Protocol

from .alert import Alert, Candidate
from .inhibit import Rule
from .notify import Notice, Notifier, Silence
from .timed import TimedMonitors
from .voa import Voa

log = logging.getLogger(__name__)
Sink = Callable[[Alert], None]
NoticeSink = Callable[[Notice], None]


class Domain(Protocol):
    """What a domain module plugs into the manager."""

    def bind(self, ea: "ExecutionAssistant") -> None: ...
    def start(self, t: float) -> None: ...                      # initialize the plan (global monitors)
    def watch(self, msg) -> object | None: ...                  # watchman: filter, update the picture
    def apply(self, facts: list) -> None: ...                   # post a batch of facts
    def detect(self, t: float) -> list[Candidate]: ...          # detectors at epoch end
    def busy(self) -> bool: ...                                 # anything changed since last detect?
    def next_wakeup(self) -> float: ...                         # next time detect must run anyway
    def merge(self, key, cands: list[Candidate]) -> Candidate: ...
    def to_alert(self, c: Candidate) -> Alert: ...
    # optional: BULK_FACTS, the fact types that may wait in a batch (see ExecutionAssistant.submit)


class ExecutionAssistant:
    def __init__(self, owner: str, domain: Domain, cfg: dict, sinks: Iterable[Sink] = (), voa: bool = True):
        self.owner = owner
        self.cfg = cfg
        self.domain = domain
        self.sinks = list(sinks)
        self.timers = TimedMonitors()
        self.voa = Voa(cfg, domain.merge, enabled=voa)
        self.batch = max(1, int(cfg["manager"]["fact_batch"]))
        self.epoch_s = float(cfg["manager"]["epoch_s"])
        self.epoch_end = self.epoch_s
        self.pending: list = []
        self.posted: list[Candidate] = []   # candidates posted by timers and mission methods
        self.alerts: list[Alert] = []
        self.stats: Counter = Counter()
        self.errors: list[str] = []
        self._next_forget = 60.0
        self.n_in = 0
        self.now = 0.0                # the latest scenario time seen (commands take effect at it)
        self.notice_sinks: list[NoticeSink] = []   # this EA's re-notifications and escalations (not alerts)
        self.inbox_sinks: list[NoticeSink] = []    # escalations from subordinates' EAs (take_notice)
        self.notices: list[Notice] = []             # given by this EA
        self.received: list[Notice] = []            # escalations from subordinates' EAs
        self.notify = Notifier(owner, cfg, self._superior)
        self.changes = self.notify.changes   # threshold changes made at run time, as applied
        self._watch = domain.watch    # bound once: this is the per-message hot path
        bulk = getattr(domain, "BULK_FACTS", None)   # None: every fact may wait in a batch
        self._bulk: frozenset | None = None if bulk is None else frozenset(bulk)
        domain.bind(self)

    # -- input -----------------------------------------------------------------------
    def start(self, t: float = 0.0) -> None:
        self.epoch_end = (math.floor(t / self.epoch_s) + 1) * self.epoch_s
        self.domain.start(t)

    def submit(self, msg) -> None:
        """One incoming message; never raises for bad input (counted and logged instead)."""
        self.n_in += 1
        t = msg.t
        if t > self.now:
            self.now = t
        if t > self.epoch_end:   # finish earlier epochs before the watchman sees later data
            if t > self.now:
                self.now = t
            self.process()
            self._close_until(t, strict=True)
        try:
            fact = self._watch(msg)
        except (KeyError, ValueError, TypeError) as e:
            self.error(f"{type(msg).__name__} at t={t}: {e}")
            return
        if fact is not None:
            self.pending.append(fact)
            # a fact not of the domain's bulk kinds (a confirmation, a call for fire) is
            # applied at once: its handler reads the picture, which must hold exactly the
            # reports before it, wherever the batch boundaries fall (a peer hears fewer
            # messages than an in-process EA: its batches are not the same)
            if len(self.pending) >= self.batch or self._bulk is not None and type(fact) not in self._bulk:
                self.process()

    def error(self, text: str) -> None:
        self.stats["errors"] += 1
        self.errors = (self.errors + [text])[-50:]
        log.warning("EA %s: %s", self.owner, text)

    def post(self, c: Candidate) -> None:
        """Mission methods and timed monitors post candidates here."""
        self.posted.append(c)

    # -- the loop --------------------------------------------------------------------
    def process(self) -> None:
        """Hand pending facts to the domain, closing epochs as scenario time passes."""
        facts, self.pending = self.pending, []
        self.stats["in"] = self.n_in
        self.stats["facts"] += len(facts)
        start = 0
        for i, f in enumerate(facts):
            if f.t > self.epoch_end:
                if i > start:
                    self._apply(facts[start:i])
                    start = i
                self._close_until(f.t, strict=True)
        if start < len(facts):
            self._apply(facts[start:])

    def _apply(self, facts: list) -> None:
        self.stats["batches"] += 1
        try:
            self.domain.apply(facts)   # the domain reports per-fact problems through error()
        except (KeyError, ValueError, TypeError) as e:  # a bug-level failure: count it, keep running
            self.error(f"batch of {len(facts)} facts from t={facts[0].t}: {e}")

    def advance(self, t: float, strict: bool = False) -> None:
        """Scenario time reached t: process what is pending and close finished epochs
        (`strict`: facts at t itself may still come, as after a clock tick that promises
        only what is before it: the epoch ending at t stays open)."""
        if t > self.now:
            self.now = t
        self.process()
        self._close_until(t, strict)

    def _close_until(self, t: float, strict: bool = False) -> None:
        """Close the epochs that end at or before t (`strict`: before t, when a fact at t
        is still to come: an epoch (end - epoch_s, end] holds the facts at its very end,
        so one whose sources promised `end` closes at once, not an epoch later)."""
        ep = self.epoch_s
        while self.epoch_end < t or not strict and self.epoch_end == t:
            if not self.posted and not self.notify.pending and not self.domain.busy():
                # the first epoch end at or after a timer's deadline, the domain's and the
                # notifier's next due time
                dl = min(self.timers.next_deadline(), self.domain.next_wakeup(), self.notify.next_due())
                nxt = math.ceil(dl / ep) * ep if math.isfinite(dl) else math.inf
                target = max(self.epoch_end, nxt)
                if target > t or strict and target == t:  # idle until t or after: skip the empty epochs
                    self.epoch_end = max(self.epoch_end, math.ceil(t / ep) * ep)
                    if not strict and self.epoch_end == t:
                        self.epoch_end += ep
                    break
                self.epoch_end = target
            self._close_epoch(self.epoch_end)
            self.epoch_end = round(self.epoch_end / ep + 1) * ep

    def _close_epoch(self, end: float) -> None:
        self.stats["epochs"] += 1
        if end >= self._next_forget:   # keep memory bounded: expired history no longer counts anyway
            self.voa.forget_before(end - self.voa.expiry)   # a margin for late-posted timer candidates
            self.notify.forget_before(end - self.notify.story_s)
            self._next_forget = end + 60.0
        if self.notify.pending:   # thresholds changed by a commander count from this epoch on
            self.stats["settings"] += len(self.notify.apply_pending(end, self.voa))
        notify = self.notify
        if notify.silences:
            notify.expire(end)
        for n in notify.notices_until(end) if notify.due else ():
            self.stats["renotifications" if n.kind == "renotify" else "escalations"] += 1
            self.notices.append(n)
            for s in self.notice_sinks:
                s(n)
        self.timers.advance(end)
        found = self.domain.detect(end)   # may post more (mission responses)
        cands, self.posted = self.posted + found, []
        if not cands:
            return
        cands.sort(key=lambda c: (c.t, c.type, c.subjects))
        issued = self.voa.merge(self.voa.judge(cands))
        for c in issued:
            self.emit(self.domain.to_alert(c))

    def emit(self, alert: Alert) -> Alert:
        """Give an alert: its id and silence mark first (notify), then the sinks."""
        alert = self.notify.stamp(alert)
        if "silenced" in alert.details:
            self.stats["silenced"] += 1
        elif "inhibited_by" in alert.details:
            self.stats["inhibited"] += 1
        self.alerts.append(alert)
        self.stats["alerts"] += 1
        self.voa.remember(alert.t, alert.type, alert.subjects, alert.details.get("places", ()))
        for s in self.sinks:
            s(alert)
        return alert

    def _superior(self) -> str | None:
        """The unit above this EA's in the task organization as the domain knows it now."""
        to = getattr(self.domain, "taskorg", None)
        return to.parent.get(self.owner) if to is not None else None

    def take_notice(self, n: Notice, budgeted: bool = False) -> None:
        """An escalation from a subordinate's EA reached this one: told to its sinks (the
        notice log, the console), never as an alert of this EA. Charged to this commander's
        notice budget unless the sender already asked it (`budgeted`: run in one process)."""
        self.stats["escalations_in"] += 1
        if not budgeted:
            self.notify.budget.charge(n.t)
        self.received.append(n)
        for s in self.inbox_sinks:
            s(n)

    # -- a commander's actions (docs/console.md 1); bad input raises, changing nothing --
    def arm(self, ack_after_s: float | None = None) -> None:
        """A commander is in the loop: urgent alerts given from now on are re-notified and
        escalated until acknowledged. `ack_after_s`: a modelled commander who acknowledges
        each urgent alert that long after it is raised (evaluate --commander)."""
        self.notify.armed = True
        if ack_after_s is not None:
            self.notify.ack_after_s = float(ack_after_s)

    def ack(self, alert_id: str, t: float | None = None) -> dict:
        """Acknowledge an alert: its re-notifications and escalation stop. KeyError if unknown."""
        out = self.notify.ack(alert_id, self.now if t is None else t)
        self.stats["acks"] += 1
        return out

    def silence(self, sid: str, types=(), subjects=(), areas=(), until_t: float = 0.0, comment: str = "",
                t: float | None = None) -> Silence:
        """Mark matching alerts silenced until scenario time `until_t` (ValueError if malformed)."""
        s = self.notify.silence(sid, types, subjects, areas, until_t, comment, self.now if t is None else t)
        self.stats["silences"] += 1
        return s

    def unsilence(self, sid: str) -> Silence:
        return self.notify.unsilence(sid)

    def inhibit(self, rule: dict) -> Rule:
        """Add (or replace) an inhibition rule from now on (ValueError if malformed)."""
        r = self.notify.inhibit(rule)
        self.stats["inhibits"] += 1
        return r

    def uninhibit(self, rid: str) -> Rule:
        return self.notify.uninhibit(rid)

    def set_param(self, key: str, value, t: float | None = None):
        """Change a `voi.*`/`voa.*` threshold from the next epoch close on (ConfigError if bad)."""
        return self.notify.set_param(key, value, self.now if t is None else t)

    def finish(self, t: float) -> list[Alert]:
        """End of input at scenario time t: flush everything."""
        self.advance(t)
        if self.posted or self.notify.pending or self.domain.busy():
            self._close_epoch(self.epoch_end)
        return self.alerts
