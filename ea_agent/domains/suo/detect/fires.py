"""Calls for fire (paper 6.7.2, case 1): friendlies near the target of a call for
fire we make, or of a confirmed fire mission near our own units."""
from __future__ import annotations

from collections import defaultdict

import numpy as np

from ea_agent.core.alert import Candidate

from ..messages import CallForFire, CallForFireConfirm
from ..render import km
from .base import Detector, platoon_of


class CallsForFire(Detector):
    """Alerts at once, when the call arrives: there is no waiting for the epoch."""
    TYPES = {"call-for-fire": "policy-constraint-violated"}
    FACTS = (CallForFire, CallForFireConfirm)

    def on_fact(self, f) -> None:
        dom = self.dom
        dom.flush_quiet()   # the target area is judged on every position we know, relevant or not
        pic = dom.pic
        x, y = pic.proj.to_xy(f.lon, f.lat)
        d = np.hypot(pic.xy[:, 0] - x, pic.xy[:, 1] - y)
        near = np.nonzero(d <= f.radius_m)[0]
        confirm = type(f) is CallForFireConfirm
        if not confirm and f.requester != dom.owner:
            return
        units: dict[str, list[float]] = defaultdict(list)
        for i in near.tolist():
            leaf = pic.ent_leaf[i]
            if confirm and leaf not in dom.own_leaves:
                continue
            if not confirm and leaf in dom.taskorg.subtree(f.requester):
                continue   # the requester's own elements are its own business
            units[platoon_of(dom.taskorg, leaf)].append(float(d[i]))
        if not units:
            return
        names = ", ".join(f"{dom.name(u)} ({len(v)} within {km(min(v))})" for u, v in sorted(units.items()))
        text = (f"Planned fire {f.cff} by {dom.name(f.requester)} near {names}" if confirm else
                f"Friendlies near target of {f.cff}: {names}; confirm before firing")
        dom.ea.post(Candidate(f.t, "call-for-fire", "flash", tuple(sorted(units)), text,
                              key=("cff", f.cff, confirm), friendly=True,
                              details={"cff": f.cff, "requester": f.requester, "confirmed": confirm,
                                       "radius_m": f.radius_m}))
