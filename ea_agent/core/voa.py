"""Value of an alert (paper 5, 6.7): histories, expiry, suppression, repeats, merging.

Like Alertmanager's inhibit/silence stages, VOA only decides; detectors only
propose. A candidate is judged against the last alert given on its `key`:
 - no unexpired alert on that key: give it (an alert expires `expiry_s` after its story
   was last active: a candidate on the key, or `touch`; a situation that goes on is
   not told again because the user might have forgotten it);
 - a candidate with `news` (subjects the user was never told of on that key, e.g. a
   new group in a watched area): give it;
 - a candidate that counts more entities (`count`) than the alert last told on its key,
   in subjects that alert did not name (a group's members joining it): news, given at
   once at its own priority; the suppression interval is for repeats, not growth;
 - a similar alert inside the suppression interval (90 s hostile, 120 s friendly): drop;
 - otherwise give it only if its measure crossed the repeat ratio (progressive
   repeat), at one priority lower: the user already knows the gist;
 - after a projection of the same violation (`Candidate.projection` set the key's
   history), the actual violation is the same story: dropped, unless its measure crossed
   the repeat ratio, and then given at its own priority (the projection came true, worse).
"""
from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass
from typing import Callable, Hashable, Iterable

from .alert import Candidate, lower


@dataclass(slots=True)
class Record:
    t: float
    measure: float | None
    priority: str
    projected: bool = False   # set by a projection of the violation this key stands for
    seen: float = 0.0         # when the story was last active (a candidate on the key, or touch)
    count: int | None = None  # the entities it counted
    told: frozenset = frozenset()   # the subjects it named


def grew(c: Candidate, rec: Record) -> bool:
    """Whether `c` counts more entities than `rec` told, some in subjects `rec` did not name:
    members who joined the group since are new information, not a repeat (a track whose
    own strength wavers names no new subject: the repeat ratio judges that)."""
    return (c.count is not None and rec.count is not None and c.count > rec.count
            and not rec.told.issuperset(c.subjects))


MergeFn = Callable[[Hashable, list[Candidate]], Candidate]


class Voa:
    def __init__(self, cfg: dict, merge_fn: MergeFn | None = None, enabled: bool = True):
        v = cfg["voa"]
        self.enabled = enabled
        self.expiry = float(v["expiry_s"])
        self.suppress_friendly = float(v["suppress_friendly_s"])
        self.suppress_hostile = float(v["suppress_hostile_s"])
        self.repeat: dict[str, float] = {k: float(x) for k, x in v["repeat"].items()}
        self.merge_enabled = bool(v["merge"]) and merge_fn is not None
        self.merge_fn = merge_fn
        self.history: dict[Hashable, Record] = {}
        # Histories per friendly unit, named place and map cell, for drill-down and heuristics.
        self.by_scope: dict[tuple[str, str], list[tuple[float, str]]] = defaultdict(list)
        self.stats: Counter = Counter()

    def last(self, key: Hashable, now: float) -> Record | None:
        """The unexpired alert on `key`, if any (expired alerts no longer count)."""
        rec = self.history.get(key)
        if rec is not None and now - (rec.t if rec.t > rec.seen else rec.seen) >= self.expiry:   # max(), inlined
            return None
        return rec

    def touch(self, key: Hashable, now: float) -> None:
        """The story behind `key` is still going on (a detector saw it with nothing new
        to say): its alert is not forgotten while it lasts."""
        rec = self.last(key, now)
        if rec is not None:
            rec.seen = max(rec.seen, now)

    def judge(self, cands: Iterable[Candidate]) -> list[Candidate]:
        """Issue or suppress each candidate; returns the issued ones (in input order).
        Most candidates of a run are suppressed (thousands): the history is looked up
        once per candidate and the counts are added once per call (the same counts, their
        keys first counted in the same order)."""
        out: list[Candidate] = []
        suppressed: dict[str, int] = {}
        n = 0
        history = self.history
        expiry = self.expiry
        for c in cands:
            n += 1
            if not self.enabled:
                out.append(c)
                continue
            key, t = c.key, c.t
            rec = history.get(key)   # last(), inlined: the unexpired alert on the key
            if rec is not None and t - (rec.t if rec.t > rec.seen else rec.seen) >= expiry:
                rec = None
            verdict = None if rec is None else self._verdict_on(c, rec)
            if verdict is not None:   # suppressed: its story goes on (touch(), with the record found)
                if t > rec.seen:
                    rec.seen = t
                k = "suppressed-" + verdict
                suppressed[k] = suppressed.get(k, 0) + 1
                continue
            told = frozenset(c.subjects)
            history[key] = Record(t, c.measure, c.priority, count=c.count, told=told)
            for k, measure in c.also:  # e.g. a contact sets the baseline for later distance alerts
                history[k] = Record(t, measure, c.priority, c.projection, count=c.count, told=told)
            out.append(c)
        if n:
            stats = self.stats
            stats["candidates"] += n
            for k, v in suppressed.items():
                stats[k] += v
        return out

    def _verdict(self, c: Candidate) -> str | None:
        rec = self.last(c.key, c.t)
        return None if rec is None else self._verdict_on(c, rec)

    def _verdict_on(self, c: Candidate, rec: Record) -> str | None:
        """Why `c` is suppressed given the unexpired alert `rec` on its key (None: give it)."""
        if c.news and not rec.projected:   # news, unless a projection already told it
            return None
        if grew(c, rec) and not rec.projected:
            return None
        ratio = self.repeat.get(c.type, 0.0)
        if rec.projected:   # the violation a projection told: the same story, unless much worse
            if ratio > 0.0 and c.measure is not None and rec.measure is not None and c.measure >= rec.measure * ratio:
                c.details["projected_at_t"] = rec.t   # it came, and worse: told at its own priority
                return None
            return "projected"
        if c.t - rec.t < (self.suppress_friendly if c.friendly else self.suppress_hostile):
            return "time"
        if ratio <= 0.0:
            return "once"
        if c.measure is None or rec.measure is None or c.measure < rec.measure * ratio:
            return "not-worse"
        c.repeat = True
        c.priority = lower(c.priority)
        c.details["repeat_of_t"] = rec.t
        c.details["last_alerted_measure"] = rec.measure
        return None

    def merge(self, issued: list[Candidate]) -> list[Candidate]:
        """Merge issued alerts that share a merge group into one for the common parent."""
        if not self.enabled or not self.merge_enabled:
            return issued
        groups: dict[Hashable, list[Candidate]] = {}
        order: list[Hashable | int] = []
        for i, c in enumerate(issued):
            if c.merge_group is None:
                order.append(i)
            else:
                if c.merge_group not in groups:
                    order.append(("g", c.merge_group))
                groups.setdefault(c.merge_group, []).append(c)
        out = []
        for o in order:
            if isinstance(o, int):
                out.append(issued[o])
                continue
            g = groups[o[1]]
            if len(g) == 1:
                out.append(g[0])
            else:
                self.stats["merged"] += len(g) - 1
                out.append(self.merge_fn(o[1], g))  # type: ignore[misc]
        return out

    def remember(self, alert_t: float, alert_type: str, subjects: Iterable[str],
                 places: Iterable[str] = (), cells: Iterable[str] = ()) -> None:
        for s in subjects:
            self.by_scope[("unit", s)].append((alert_t, alert_type))
        for p in places:
            self.by_scope[("place", p)].append((alert_t, alert_type))
        for c in cells:
            self.by_scope[("cell", c)].append((alert_t, alert_type))

    def forget_before(self, now: float) -> None:
        """Drop expired history so memory stays bounded on long runs."""
        cutoff = now - self.expiry
        for k in [k for k, r in self.history.items() if max(r.t, r.seen) < cutoff]:
            del self.history[k]
        for k in list(self.by_scope):
            v = [e for e in self.by_scope[k] if e[0] >= cutoff]
            if v:
                self.by_scope[k] = v
            else:
                del self.by_scope[k]
