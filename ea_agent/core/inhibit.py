"""Inhibition rules (Alertmanager's `inhibit_rules`, docs/console.md): while a *source*
alert is active, a *target* alert sharing the named labels with it is inhibited: logged,
marked `inhibited_by`, never shown as new, re-notified or escalated.

A rule comes from `[[inhibit]]` in the domain's config or from a commander at run time
(the `inhibit` command); both are checked here with one-line errors naming the field.
Everything runs on scenario time: an alert is an active source from its time until
`for_s` later, so the same alerts and commands give the same marks.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Iterable

from .alert import PRIORITIES, Alert

MATCHER_KEYS = ("types", "subjects", "priorities", "owners")
LABELS = ("subjects", "owner", "places", "category")   # what `equal` may name
RULE_KEYS = ("id", "source", "target", "equal", "for_s", "comment")
MAX_RULES = 64
MAX_SOURCES = 4096   # active source alerts remembered per rule (the newest)


@dataclass(frozen=True, slots=True)
class Matcher:
    """Every non-empty list must match (types: the alert's type, subjects: one of its
    subjects, priorities: its priority, owners: the EA that raised it)."""
    types: frozenset[str] = frozenset()
    subjects: frozenset[str] = frozenset()
    priorities: frozenset[str] = frozenset()
    owners: frozenset[str] = frozenset()

    def matches(self, a: Alert) -> bool:
        return ((not self.types or a.type in self.types)
                and (not self.subjects or not self.subjects.isdisjoint(a.subjects))
                and (not self.priorities or a.priority in self.priorities)
                and (not self.owners or a.owner in self.owners))

    def empty(self) -> bool:
        return not (self.types or self.subjects or self.priorities or self.owners)

    def to_dict(self) -> dict:
        return {k: sorted(getattr(self, k)) for k in MATCHER_KEYS if getattr(self, k)}


def _labels(a: Alert, name: str) -> frozenset:
    if name == "subjects":
        return frozenset(a.subjects)
    if name == "owner":
        return frozenset((a.owner,))
    if name == "category":
        return frozenset((a.category,))
    places = a.details.get("places", ())
    return frozenset(p for p in places if isinstance(p, str)) if isinstance(places, (list, tuple)) else frozenset()


@dataclass(frozen=True, slots=True)
class Rule:
    id: str
    source: Matcher
    target: Matcher
    equal: tuple[str, ...]
    for_s: float
    comment: str = ""

    def related(self, src: Alert, tgt: Alert) -> bool:
        """Every label named in `equal` shares a value (set-valued labels: a common one)."""
        return all(not _labels(src, k).isdisjoint(_labels(tgt, k)) for k in self.equal)

    def to_dict(self) -> dict:
        return {"id": self.id, "source": self.source.to_dict(), "target": self.target.to_dict(),
                "equal": list(self.equal), "for_s": self.for_s, "comment": self.comment}


def _names(v: Any, where: str) -> frozenset[str]:
    if not isinstance(v, (list, tuple)) or not all(isinstance(x, str) and x and len(x) <= 128 for x in v):
        raise ValueError(f"{where}: expected a list of non-empty strings")
    if len(v) > 64:
        raise ValueError(f"{where}: over 64 entries")
    return frozenset(v)


def matcher(v: Any, where: str) -> Matcher:
    if not isinstance(v, dict):
        raise ValueError(f"{where}: expected a table with any of {', '.join(MATCHER_KEYS)}")
    for k in v:
        if k not in MATCHER_KEYS:
            raise ValueError(f"{where}: field '{k}': unknown key (known: {', '.join(MATCHER_KEYS)})")
    m = Matcher(**{k: _names(v[k], f"{where}.{k}") for k in MATCHER_KEYS if k in v})
    bad = m.priorities - set(PRIORITIES)
    if bad:
        raise ValueError(f"{where}.priorities: {sorted(bad)[0]!r} is not one of {', '.join(PRIORITIES)}")
    if m.empty():
        raise ValueError(f"{where}: give at least one of {', '.join(MATCHER_KEYS)} (an empty matcher matches "
                         f"every alert)")
    return m


def rule(d: Any, where: str, default_for_s: float) -> Rule:
    """One rule from a config table or a command, checked (ValueError naming the field)."""
    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected a table")
    for k in d:
        if k not in RULE_KEYS:
            raise ValueError(f"{where}: field '{k}': unknown key (known: {', '.join(RULE_KEYS)})")
    rid = d.get("id")
    if not isinstance(rid, str) or not rid or len(rid) > 128:
        raise ValueError(f"{where}: field 'id': expected a non-empty string")
    where = f"{where} ({rid})"
    if "source" not in d or "target" not in d:
        raise ValueError(f"{where}: needs both 'source' and 'target'")
    equal = d.get("equal", [])
    if not isinstance(equal, (list, tuple)) or not all(isinstance(x, str) for x in equal):
        raise ValueError(f"{where}: field 'equal': expected a list of labels ({', '.join(LABELS)})")
    for x in equal:
        if x not in LABELS:
            raise ValueError(f"{where}: field 'equal': unknown label {x[:40]!r} (known: {', '.join(LABELS)})")
    for_s = d.get("for_s", default_for_s)
    if isinstance(for_s, bool) or not isinstance(for_s, (int, float)) or not math.isfinite(for_s) or for_s <= 0:
        raise ValueError(f"{where}: field 'for_s': expected a number > 0, got {for_s!r:.40}")
    comment = d.get("comment", "")
    if not isinstance(comment, str):
        raise ValueError(f"{where}: field 'comment': expected a string")
    return Rule(rid, matcher(d["source"], f"{where}: source"), matcher(d["target"], f"{where}: target"),
                tuple(dict.fromkeys(equal)), float(for_s), comment[:512])


class Inhibitor:
    """The rules in force and the source alerts each has seen lately."""

    def __init__(self, rules: Iterable[Any] = (), default_for_s: float = 720.0, where: str = "[[inhibit]]"):
        self.default_for_s = default_for_s
        self.rules: dict[str, Rule] = {}
        self.sources: dict[str, deque[Alert]] = {}
        for i, d in enumerate(rules):
            r = rule(d, f"{where}[{i}]", default_for_s)
            if r.id in self.rules:
                raise ValueError(f"{where}[{i}]: field 'id': {r.id!r} is given twice")
            self.add(r)

    def add(self, r: Rule) -> Rule:
        if r.id not in self.rules and len(self.rules) >= MAX_RULES:
            raise ValueError(f"inhibit: {MAX_RULES} rules in force already (lift one first)")
        self.rules[r.id] = r
        self.sources[r.id] = deque(maxlen=MAX_SOURCES)
        return r

    def remove(self, rid: str) -> Rule:
        r = self.rules.pop(rid, None) if isinstance(rid, str) else None
        if r is None:
            raise KeyError(f"uninhibit: unknown rule {str(rid)[:80]!r} (in force: "
                           f"{', '.join(sorted(self.rules)) or 'none'})")
        del self.sources[rid]
        return r

    def judge(self, a: Alert) -> dict | None:
        """{"rule", "source"} when an active source alert inhibits `a` (the newest such
        source of the first rule in order); `a` is then remembered as a source where it is one."""
        out = None
        for rid, r in self.rules.items():
            if out is None and r.target.matches(a):
                srcs = self.sources[rid]
                while srcs and srcs[0].t + r.for_s < a.t:
                    srcs.popleft()
                for s in reversed(srcs):
                    if s is not a and s.details.get("id") != a.details.get("id") and r.related(s, a):
                        out = {"rule": rid, "source": s.details.get("id", "")}
                        break
            if r.source.matches(a):
                self.sources[rid].append(a)
        return out
