"""Fire support timing: a support-by-fire unit must be in position before the unit it
supports crosses its line of departure, and its fires must lift when that unit comes
within `lift_m` of the target. Both are judged on the supported unit's reported centroid
(crossing: more than `line_margin_m` past the line, away from its start side). A
suppression's target must be within its unit's weapons range through its fire window
(judged at the window's start and whenever the unit moves or is scanned in it)."""
from __future__ import annotations

import shapely

from ea_agent.core.alert import Candidate, hms

from ..missions import Mission
from ..render import km
from .base import Changes, Detector
from .lines import side


class FireSupport(Detector):
    TYPES = {"fire-support": "plan-constraint-violated"}

    def reset(self) -> None:
        # mission -> [it, supported unit, its line or None, target, start side of the line or None, crossed, lifted]
        self.watch: dict[str, list] = {}
        # suppression -> [it, target, window from, until, told]
        self.windows: dict[str, list] = {}

    def end_mission(self, mid: str) -> None:
        self.windows.pop(mid, None)

    def post_window(self, m: Mission, target: str, t0: float, t1: float) -> None:
        """Fires of `m`'s unit due on `target` from t0 to t1: looked at when the window opens,
        then as the unit moves."""
        self.windows[m.id] = w = [m, target, t0, t1, False]
        dom = self.dom

        def opens(tf, mon, how):
            if dom.plan is not None and dom.plan.state.get(m.id) == "active" and self.windows.get(m.id) is w:
                c = self._out_of_range(w, tf)
                if c is not None:
                    dom.ea.post(c)
            return None
        dom.timers.not_later_than(("fires-due", m.id), t0, opens, tag=m.id)

    def _out_of_range(self, w: list, t: float) -> Candidate | None:
        """The window's check at `t`: the target beyond the unit's weapons range of where it is."""
        m, target, t0, t1, told = w
        dom = self.dom
        if told or not t0 <= t <= t1 or not dom.in_plan(m):
            return None
        pos = dom.unit_pos.get(m.unit)
        if pos is None:
            return None
        d = float(shapely.distance(dom.overlay[target].area, shapely.Point(pos)))
        rng = dom.coverage.weapons_range(m.unit)
        if d <= rng:
            return None
        w[4] = True
        return Candidate(
            t, "fire-support", m.compute_priority("fire-support"), (m.unit,),
            f"{dom.name(m.unit)} cannot reach {target} with fires due {hms(t0)}-{hms(t1)}: {km(d)} away, "
            f"beyond its {km(rng)} weapons range ({m.TYPE})",
            key=("fire-support", m.id, "suppress"), measure=d - rng,
            details={"mission": m.id, "check": "suppress", "target": target, "window": [t0, t1],
                     "distance_m": round(d, 1), "weapons_range_m": rng, "places": [target]})

    def post(self, m: Mission, supported: str, line: str | None, target: str) -> None:
        start = None
        if line is not None:   # the supported unit attacks towards the target: its own side is the other one
            c = self.dom.overlay[target].area.centroid
            start = -1.0 if side(self.dom.overlay[line].geom, (c.x, c.y)) > 0 else 1.0
        self.watch[m.id] = [m, supported, line, target, start, line is None, False]

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if dom.plan is None or not (ch.units or ch.rescan):
            return
        for mid, w in self.windows.items():
            if dom.plan.state.get(mid) == "active" and (ch.rescan or w[0].unit in ch.units):
                c = self._out_of_range(w, t)
                if c is not None:
                    cands.append(c)
        for mid, w in self.watch.items():
            m, sup, line, target, start, crossed, lifted = w
            if (crossed and lifted) or sup not in ch.units or not dom.in_plan(m) or \
                    dom.plan.state.get(mid) in ("done", "aborted"):
                continue
            pos = dom.unit_pos.get(sup)
            if pos is None:
                continue
            margin = dom.voi(m, "line_margin_m")
            if not crossed and side(dom.overlay[line].geom, pos) * start < -margin:
                w[5] = True
                self._in_position(m, sup, line, t, cands)
            if not lifted and dom.plan.state.get(mid) == "active":
                d = float(shapely.distance(dom.overlay[target].area, shapely.Point(pos)))
                if d <= dom.voi(m, "lift_m"):
                    w[6] = True
                    cands.append(Candidate(
                        t, "fire-support", m.compute_priority("fire-support"), (m.unit, sup),
                        f"Lift fires: {dom.name(sup)} {km(d)} from {target} ({dom.name(m.unit)} {m.TYPE})",
                        key=("fire-support", mid, "lift"), measure=d,
                        details={"mission": mid, "check": "lift", "supported": sup, "target": target,
                                 "distance_m": round(d, 1), "places": [target]}))

    def _in_position(self, m: Mission, sup: str, line: str, t: float, cands: list[Candidate]) -> None:
        """The supported unit crossed its line: the supporting unit must be on its position by now."""
        dom = self.dom
        pos = dom.unit_pos.get(m.unit)
        where = m.params["position"]
        d = float(shapely.distance(dom.overlay[where].area, shapely.Point(pos))) if pos else float("inf")
        if d <= dom.voi(m, "out_of_position_m"):
            return
        cands.append(Candidate(
            t, "fire-support", m.compute_priority("fire-support"), (m.unit, sup),
            f"{dom.name(sup)} crossed {line} with {dom.name(m.unit)} not in {where} to support it"
            + (f" ({km(d)} away)" if d != float("inf") else " (position unknown)"),
            key=("fire-support", m.id, "in-position"), measure=None if d == float("inf") else d,
            details={"mission": m.id, "check": "in-position", "supported": sup, "line": line, "position": where,
                     "distance_m": None if d == float("inf") else round(d, 1), "places": [where, line]}))
