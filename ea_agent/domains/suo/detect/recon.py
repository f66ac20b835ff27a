"""Reconnaissance progress through a zone or an area: the share of it the unit's
elements have come within sight of, against the share of the mission's time gone.
A route reconnaissance's cells are points along its route (the sections of it seen); a zone or area has no
order to its points, so what is seen is counted on a grid of cells (`recon_cell_m`),
a cell seen once an element reported within `recon_sight_m` of its centre. An area
reconnaissance's progress is the share of its cells seen (coverage, in any order); a zone
reconnaissance's is the depth passed front to rear: the bands of cells across the zone,
from the side its unit starts on, seen (each to `recon_complete`) without a gap before them."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from ea_agent.core.alert import Candidate, hms

from ..missions import Mission
from .base import Changes, Detector
from .geometry import distances

RECHECK_S = 30.0   # progress is judged this often while the mission runs


@dataclass(slots=True)
class _Recon:
    m: Mission
    area: str
    cells: np.ndarray        # (n, 2) centres of the grid cells inside the area
    seen: np.ndarray         # (n,) bool: an element came within sight of it
    by: float | None         # when all of it must be seen (None: judged at the end only)
    progress: str = "coverage"   # coverage | depth
    bands: np.ndarray | None = None   # depth: each cell's band index, front (0) to rear (None until oriented)
    next_check: float = 0.0

    def share(self, complete: float) -> float:
        """How far along it is: cells seen, or bands passed front to rear without a gap."""
        if self.progress == "coverage":
            return float(self.seen.mean())
        if self.bands is None:
            return 0.0
        n = int(self.bands.max()) + 1
        seen = np.bincount(self.bands, weights=self.seen, minlength=n)
        total = np.bincount(self.bands, minlength=n)
        ok = seen >= complete * total
        return float(np.argmin(ok)) / n if not ok.all() else 1.0


def along(line, step: float) -> np.ndarray:
    """Points every `step` along a route, both ends included: the sections a route
    reconnaissance must see."""
    n = max(1, math.ceil(line.length / step))
    pts = [line.interpolate(i * line.length / n) for i in range(n + 1)]
    return np.array([[p.x, p.y] for p in pts])


def grid_cells(area, step: float) -> np.ndarray:
    """Centres of a `step` grid inside `area` (its representative point if it is smaller)."""
    x0, y0, x1, y1 = area.bounds
    xs, ys = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
    xs, ys = xs.ravel(), ys.ravel()
    inside = shapely.contains_xy(area, xs, ys)
    if not inside.any():
        p = area.representative_point()
        return np.array([[p.x, p.y]])
    return np.column_stack([xs[inside], ys[inside]])


class ReconProgress(Detector):
    TYPES = {"recon-progress": "plan-constraint-violated"}

    def reset(self) -> None:
        self.watch: dict[str, _Recon] = {}

    def post(self, m: Mission, area: str, by: float | None, progress: str = "coverage") -> None:
        dom = self.dom
        f = dom.overlay[area]
        step = dom.voi(m, "recon_cell_m")
        cells = along(f.geom, step) if f.geom.geom_type == "LineString" else grid_cells(f.area, step)
        self.watch[m.id] = w = _Recon(m, area, cells, np.zeros(len(cells), dtype=bool), by, progress)
        self._look(w)   # what it sees from where it starts

    def start(self, m: Mission) -> None:
        """The mission started: a zone is oriented from where its unit is now (the picture as of
        the confirmation, the same in every peer)."""
        w = self.watch.get(m.id)
        if w is not None:
            self._orient(w, self.dom.pic.centroid(m.unit))

    def _orient(self, w: _Recon, pos: tuple[float, float] | None = None) -> None:
        """A zone's depth runs from where its unit is at its start (or, unknown then, when first
        known while the mission runs) towards the zone's centre: bands `recon_cell_m` deep across
        that direction."""
        if w.progress != "depth" or w.bands is not None:
            return
        pos = pos or self.dom.unit_pos.get(w.m.unit)
        if pos is None:
            return
        c = self.dom.overlay[w.area].area.centroid
        dx, dy = c.x - pos[0], c.y - pos[1]
        n = math.hypot(dx, dy)
        ux, uy = (dx / n, dy / n) if n > 1.0 else (0.0, -1.0)   # on its centre: north to south
        depth = w.cells[:, 0] * ux + w.cells[:, 1] * uy
        w.bands = np.floor((depth - depth.min()) / self.dom.voi(w.m, "recon_cell_m") + 1e-9).astype(int)

    def end_mission(self, mid: str) -> None:
        self.watch.pop(mid, None)

    def _look(self, w: _Recon) -> None:
        """Cells newly within sight of the unit's reported elements."""
        todo = np.flatnonzero(~w.seen)
        if not len(todo):
            return
        pts = self.dom.pic.member_xy(w.m.unit)
        if not len(pts):
            return
        near = distances(w.cells[todo], pts).min(axis=1) <= self.dom.voi(w.m, "recon_sight_m")
        w.seen[todo[near]] = True

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if not self.watch or dom.plan is None:
            return
        for mid, w in self.watch.items():
            if dom.plan.state.get(mid) != "active" or not dom.in_plan(w.m):
                continue
            due = ch.rescan and t >= w.next_check and w.by is not None
            self._orient(w)
            if w.m.unit in ch.units or due:   # a unit that does not move sees what it saw
                self._look(w)
            if not due:
                continue
            w.next_check = t + RECHECK_S
            t0 = dom.plan.started.get(mid, t)
            if w.by <= t0:
                continue
            expected = min(1.0, (t - t0) / (w.by - t0))
            got = w.share(dom.voi(w.m, "recon_complete"))
            if expected - got > dom.voi(w.m, "recon_lag"):
                cands.append(self._cand(w, t, "behind", got, expected))

    def check_final(self, m: Mission, t: float) -> None:
        """At the mission's end: too little of the zone or area seen."""
        w = self.watch.get(m.id)
        if w is None:
            return
        self._orient(w)
        self._look(w)
        got = w.share(self.dom.voi(m, "recon_complete"))
        if got < self.dom.voi(m, "recon_complete"):
            self.dom.ea.post(self._cand(w, t, "incomplete", got, 1.0))

    def _cand(self, w: _Recon, t: float, how: str, got: float, expected: float) -> Candidate:
        dom, m = self.dom, w.m
        what = "seen" if w.progress == "coverage" else "of its depth passed"
        if how == "behind":
            text = (f"{dom.name(m.unit)} behind in its {m.TYPE} of {w.area}: {got:.0%} {what}, "
                    f"{expected:.0%} due (all by {hms(w.by)})")
        else:
            text = f"{dom.name(m.unit)} ended its {m.TYPE} of {w.area} with {got:.0%} {what}"
        return Candidate(t, "recon-progress", m.compute_priority("recon-progress"), (m.unit,), text,
                         key=("recon-progress", m.id, how), measure=max(expected - got, 1e-6),
                         details={"mission": m.id, "check": how, "area": w.area, "progress": w.progress,
                                  "seen": round(got, 3),
                                  "expected": round(expected, 3),
                                  "behind_by": round(expected - got, 3), "cells": len(w.cells), "places": [w.area]})
