"""Reconnaissance progress through a zone or an area: the share of it the unit's
elements have come within sight of, against the share of the mission's time gone.
A route reconnaissance reports progress by its checkpoints; a zone or area has no
order to its points, so what is seen is counted on a grid of cells (`recon_cell_m`),
a cell seen once an element reported within `recon_sight_m` of its centre."""
from __future__ import annotations

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
    next_check: float = 0.0


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

    def post(self, m: Mission, area: str, by: float | None) -> None:
        dom = self.dom
        cells = grid_cells(dom.overlay[area].area, dom.voi(m, "recon_cell_m"))
        self.watch[m.id] = w = _Recon(m, area, cells, np.zeros(len(cells), dtype=bool), by)
        self._look(w)   # what it sees from where it starts

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
            if w.m.unit in ch.units or due:   # a unit that does not move sees what it saw
                self._look(w)
            if not due:
                continue
            w.next_check = t + RECHECK_S
            t0 = dom.plan.started.get(mid, t)
            if w.by <= t0:
                continue
            expected = min(1.0, (t - t0) / (w.by - t0))
            got = float(w.seen.mean())
            if expected - got > dom.voi(w.m, "recon_lag"):
                cands.append(self._cand(w, t, "behind", got, expected))

    def check_final(self, m: Mission, t: float) -> None:
        """At the mission's end: too little of the zone or area seen."""
        w = self.watch.get(m.id)
        if w is None:
            return
        self._look(w)
        got = float(w.seen.mean())
        if got < self.dom.voi(m, "recon_complete"):
            self.dom.ea.post(self._cand(w, t, "incomplete", got, 1.0))

    def _cand(self, w: _Recon, t: float, how: str, got: float, expected: float) -> Candidate:
        dom, m = self.dom, w.m
        if how == "behind":
            text = (f"{dom.name(m.unit)} behind in its {m.TYPE} of {w.area}: {got:.0%} seen, "
                    f"{expected:.0%} due (all by {hms(w.by)})")
        else:
            text = f"{dom.name(m.unit)} ended its {m.TYPE} of {w.area} with {got:.0%} of it seen"
        return Candidate(t, "recon-progress", m.compute_priority("recon-progress"), (m.unit,), text,
                         key=("recon-progress", m.id, how), measure=max(expected - got, 1e-6),
                         details={"mission": m.id, "check": how, "area": w.area, "seen": round(got, 3),
                                  "expected": round(expected, 3),
                                  "behind_by": round(expected - got, 3), "cells": len(w.cells), "places": [w.area]})
