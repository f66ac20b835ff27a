"""No-status (paper 7.5): a robot that has not reported its state for `no_status_s`
(default 5 s). Runs on scenario time even when nothing arrives: `wakeup` tells the
manager when the next robot falls silent (or is due a reminder)."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..watchman import NEG

if TYPE_CHECKING:
    from ..domain import UvDomain


def last_heard(dom: "UvDomain", rid: str) -> float:
    r = dom.robots[rid]
    return r.t if r.t != NEG else dom.t0


def no_status(dom: "UvDomain", t: float, cands: list) -> None:
    thr = float(dom.uv["no_status_s"])
    for rid in dom.mine_sorted:
        last = last_heard(dom, rid)
        silent = t - last
        if silent >= thr:
            never = dom.robots[rid].t == NEG
            cands.append(dom.cand(t, "no-status", None, (rid,),
                                  f"No status from {dom.name(rid)} for {silent:.0f} s"
                                  + (" (never reported)" if never else ""), ("no-status", rid), silent,
                                  {"robot": rid, "last_state_t": None if never else last, "silent_s": round(silent, 1)}))


def wakeup(dom: "UvDomain", now: float) -> float:
    """The next time a robot becomes silent for `no_status_s`, or a silent one is due a
    look again (every `no_status_s`, for VOA's progressive repeats)."""
    thr = float(dom.uv["no_status_s"])
    best = math.inf
    for rid in dom.mine_sorted:
        last = last_heard(dom, rid)
        due = last + thr
        if due <= now:
            due = last + thr * (math.floor((now - last) / thr) + 1)
        best = min(best, due)
    return best
