"""Doctrinal time windows as in-window timed monitors (paper 6.6.4): a link-up or a relief
in place made at its point within its `window`, a passage of lines completed within its
`complete_window`, a planned fire (a mission's `fires`) confirmed within its window.

Each is armed when its mission starts; the fact that meets it disarms it, and a window
that closes unmet is told once, at its close (a fact that comes later changes nothing).
A passage completed, or a fire confirmed, before its window opens is told once, at once
(early); a link-up made before its window is no failure: it is judged while the window
is open (the two units are there then, or not)."""
from __future__ import annotations

import math
from typing import Any

from ea_agent.core.alert import Candidate, hms

from ..messages import CallForFireConfirm
from ..missions import Mission
from .base import Changes, Detector

# mission type -> its window parameter and what meets it
WINDOWED: dict[str, tuple[str, str]] = {
    "link-up": ("window", "meet"),
    "relief-in-place": ("window", "meet"),
    "passage-of-lines": ("complete_window", "end"),
}
FIRE_KEYS = {"cff": "id of the call for fire (the `cff` of its cff-confirm event)",
             "window": "[from, until]: the scenario times in which it must be confirmed",
             "requester": "optional unit that calls and confirms it (default: the mission's unit)"}


def window_problem(w: Any) -> str | None:
    """What is wrong with a [from, until] window of scenario times, if anything."""
    if (not isinstance(w, list) or len(w) != 2
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in w)):
        return "expected [from, until] in scenario seconds (finite numbers)"
    if not 0 <= w[0] < w[1]:
        return f"from {w[0]} is not before until {w[1]} (or is negative)"
    return None


def param_problem(typ: str, params: dict, units: set[str] | None = None) -> tuple[str, str] | None:
    """(field, why) for a bad window parameter of a mission of type `typ` (`units`: the task
    organization's, that a planned fire's requester must be one of), or None: checked on
    load for every mission, so a window never fails at run time."""
    key = WINDOWED.get(typ, (None,))[0]
    if key is not None and params.get(key) is not None and (why := window_problem(params[key])):
        return key, why
    fires = params.get("fires")
    if fires is None:
        return None
    if not isinstance(fires, list):
        return "fires", "expected a list of planned fires [{cff, window}]"
    seen: set[str] = set()
    for i, f in enumerate(fires):
        where = f"fires[{i}]"
        if not isinstance(f, dict):
            return where, "expected {cff, window}"
        unknown = sorted(set(f) - set(FIRE_KEYS))
        if unknown:
            return f"{where}.{unknown[0]}", f"unknown key (a planned fire has {', '.join(FIRE_KEYS)})"
        cff = f.get("cff")
        if not isinstance(cff, str) or not cff:
            return f"{where}.cff", "expected the id of a call for fire"
        if cff in seen:
            return f"{where}.cff", f"{cff!r} planned twice in this mission"
        seen.add(cff)
        req = f.get("requester")
        if req is not None and (not isinstance(req, str) or units is not None and req not in units):
            return f"{where}.requester", f"unknown unit {req!r}"
        if "window" not in f:
            return f"{where}.window", "missing (a planned fire is confirmed within a window)"
        if why := window_problem(f["window"]):
            return f"{where}.window", why
    return None


def planned_fires(m: Mission) -> list[tuple[str, str, float, float]]:
    """(cff, requester, from, until) of the mission's planned fires."""
    return [(f["cff"], f.get("requester") or m.unit, float(f["window"][0]), float(f["window"][1]))
            for f in m.params.get("fires") or ()]


class Windows(Detector):
    """The in-window monitors of the missions that have one. Alerts only through the
    timers (at a window's close, or when a fact comes early), never from `detect`."""
    FACTS = (CallForFireConfirm,)

    def reset(self) -> None:
        # link-ups and reliefs whose window is armed and not yet met: mission -> (it, from, until)
        self.meets: dict[str, tuple[Mission, float, float]] = {}
        self.armed: set[Mission] = set()   # missions whose windows are armed (once each; a branch's task is another)

    def start(self, m: Mission, t: float) -> None:
        """Mission `m` started at t: arm its windows (once, however often it is posted again)."""
        dom = self.dom
        if m in self.armed or not dom.in_plan(m):
            return
        self.armed.add(m)
        spec = WINDOWED.get(m.TYPE)
        if spec is not None and m.params.get(spec[0]) is not None:
            lo, hi = (float(x) for x in m.params[spec[0]])
            if spec[1] == "meet":
                self.meets[m.id] = (m, lo, hi)
                dom.timers.in_window(("window", m.id), lo, hi, self._failed(m, spec[0], lo, hi, t), tag=m.id)
            else:   # a passage is complete when its mission ends
                dom.timers.in_window(("end", m.id), lo, hi, self._failed(m, spec[0], lo, hi, t), tag=m.id)
        for cff, req, lo, hi in planned_fires(m):
            dom.timers.in_window(("cff-confirm", cff, req), lo, hi, self._failed(m, "fires", lo, hi, t, cff),
                                 tag=m.id)

    def _failed(self, m: Mission, what: str, lo: float, hi: float, armed: float, cff: str | None = None):
        def failed(tf: float, mon, how: str) -> None:
            dom = self.dom
            if not dom.in_plan(m) or dom.missions.get(m.id) is not m:
                return None
            if how == "late" and what == "window" and self._met(m):   # there at the very close: met
                self.meets.pop(m.id, None)
                return None
            self.meets.pop(m.id, None)
            dom.ea.post(self.candidate(m, what, lo, hi, max(tf, armed), how, cff))
            return None   # told once: never re-armed
        return failed

    def _met(self, m: Mission) -> bool:
        """Both units with an element at the point now (as Coordination judges a meeting)."""
        dom = self.dom
        radius = float(dom.voi(m, "coordination_radius_m"))
        point = m.params["point"]
        return all(dom.coordination._within(point, u, radius) for u in (m.unit, m.params["partner"]))

    def on_fact(self, f) -> None:
        self.dom.timers.occurred(("cff-confirm", f.cff, f.requester), f.t)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        if not self.meets or not ch.units:
            return
        for mid, (m, lo, hi) in list(self.meets.items()):
            if t < lo or t > hi:
                continue   # made before its window opens is not yet made in it; after its close, told
            if (m.unit in ch.units or m.params["partner"] in ch.units) and self._met(m):
                self.dom.timers.occurred(("window", mid), t)
                del self.meets[mid]

    def candidate(self, m: Mission, what: str, lo: float, hi: float, t: float, how: str,
                  cff: str | None) -> Candidate:
        dom = self.dom
        span = f"{hms(lo)}-{hms(hi)}"
        who = dom.name(m.unit)
        details = {"mission": m.id, "window": [lo, hi], "how": how, "check": what}
        if cff is not None:
            text = (f"Planned fire {cff} of {who} confirmed early, before its window {span}" if how == "early" else
                    f"Planned fire {cff} of {who} not confirmed in its window {span}")
            return Candidate(t, "fire-support", m.compute_priority("fire-support"), (m.unit,), text,
                             key=("fire-window", m.id, cff), details={**details, "cff": cff})
        partner, point = m.params["partner"], m.params["point"]
        if what == "window":
            text = f"{who} and {dom.name(partner)} did not {m.TYPE} at {point} in its window {span}"
        elif how == "early":
            text = f"{who} completed its passage of {dom.name(partner)} at {point} early, before its window {span}"
        else:
            text = f"{who} did not complete its passage of {dom.name(partner)} at {point} in its window {span}"
        return Candidate(t, "coordination", m.compute_priority("coordination"), (m.unit, partner), text,
                         key=("coordination", m.id, what), details={**details, "point": point, "places": [point]})
