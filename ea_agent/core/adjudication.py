"""Adjudication: every peer turns the track reports it holds into the same picture,
whatever order they arrived in (docs/adjudication.md).

The picture is a pure function of the latest report per (source, track):
 1. per (source, track) keep the report with the greatest (t, strength, lon, lat);
 2. link live reports of *different* sources closer than `merge_m`; each connected
    component is one hostile entity;
 3. its identity is the smallest "source/track" name in it (stable while that
    report lives), its position that of its newest report (ties: smallest name),
    its strength the largest reported.
A report with a velocity (a dead-reckoned track: its node reports only when the
extrapolation errs) is extrapolated to the picture's time, from the time it describes,
for at most `extrapolate_s`; reports without one stay where they were seen.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(slots=True, frozen=True)
class Report:
    t: float
    source: str
    track: str
    x: float
    y: float
    strength: int
    lon: float
    lat: float
    vx: float = 0.0
    vy: float = 0.0
    at: float | None = None   # the time x, y describe (default t)

    @property
    def name(self) -> str:
        return f"{self.source}/{self.track}"

    def rank(self) -> tuple:
        return (self.t, self.strength, self.lon, self.lat)


@dataclass(slots=True, frozen=True)
class Entity:
    id: str
    x: float
    y: float
    strength: int
    t: float
    lon: float
    lat: float
    members: tuple[str, ...]


def _first(pair: tuple):
    return pair[0]


class Adjudicator:
    def __init__(self, merge_m: float = 500.0, extrapolate_s: float = 60.0):
        self.merge_m, self.extrapolate_s = merge_m, extrapolate_s
        self.latest: dict[tuple[str, str], Report] = {}
        self._moving: bool | None = False   # moving(), cached until a report is kept (None: stale)

    def moving(self) -> bool:
        """Whether a live report has a velocity (the picture changes with time alone).
        Asked every epoch; it can only change when update() keeps a report."""
        if self._moving is None:
            self._moving = any(r.strength > 0 and (r.vx or r.vy) for r in self.latest.values())
        return self._moving

    def update(self, r: Report) -> bool:
        """Keep r if it is newer than what we hold for its (source, track); True if kept."""
        k = (r.source, r.track)
        cur = self.latest.get(k)
        if cur is not None and r.rank() <= cur.rank():
            return False
        self.latest[k] = r
        self._moving = None
        return True

    def picture(self, now: float | None = None) -> dict[str, Entity]:
        """The entities, positions extrapolated to `now` (None: as reported)."""
        named = sorted(((f"{r.source}/{r.track}", r) for r in self.latest.values() if r.strength > 0),
                       key=_first)   # each name built once (stable sort: the order of sorting by r.name)
        n = len(named)
        if n == 0:
            return {}
        live = [r for _, r in named]
        xy = np.array([self._at(r, now) for r in live])
        d = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
        src = np.array([r.source for r in live])
        link = (d <= self.merge_m) & (src[:, None] != src[None, :])
        comp = list(range(n))

        def find(i):
            while comp[i] != i:
                comp[i] = comp[comp[i]]
                i = comp[i]
            return i
        ii, jj = np.nonzero(link)   # the upper triangle, in row order (cheaper than np.triu)
        upper = ii < jj
        ii, jj = ii[upper], jj[upper]
        for i, j in zip(ii.tolist(), jj.tolist()):
            a, b = find(i), find(j)
            if a != b:
                comp[max(a, b)] = min(a, b)
        groups: dict[int, list[tuple[str, Report]]] = {}
        for i, nr in enumerate(named):
            groups.setdefault(find(i), []).append(nr)
        out = {}
        for members in groups.values():
            if len(members) == 1:   # the usual entity: one report, which the rules below pick alike
                name, r = members[0]
                bx, by = self._at(r, now)
                out[r.track] = Entity(r.track, bx, by, r.strength, r.t, r.lon, r.lat, (name,))
                continue
            tmax = max(r.t for _, r in members)
            top = [nr for nr in members if nr[1].t == tmax]
            # the newest report; ties (rare) as the full key says, the first of equals kept
            best = top[0][1] if len(top) == 1 else \
                max(top, key=lambda nr: (nr[1].t, tuple(-ord(c) for c in nr[0])))[1]
            ident = min((r.track, r.source) for _, r in members)[0]   # fusion nodes prefix their track ids
            bx, by = self._at(best, now)
            out[ident] = Entity(ident, bx, by, max(r.strength for _, r in members), best.t, best.lon, best.lat,
                                tuple(sorted(name for name, _ in members)))
        return out

    def _at(self, r: Report, now: float | None) -> tuple[float, float]:
        if now is None or not (r.vx or r.vy):
            return r.x, r.y
        dt = min(max(now - (r.t if r.at is None else r.at), 0.0), self.extrapolate_s)
        return r.x + r.vx * dt, r.y + r.vy * dt
