"""No-status (paper 7.5): a robot that has not reported its state for `no_status_s`
(default 5 s). Runs on scenario time even when nothing arrives: `wakeup` tells the
manager when the next robot falls silent (or is due a reminder).

Whom an EA watches: its own robot(s) (the TEAM: every robot, heard or not), and, on a
robot's EA, every teammate it was hearing. A teammate's silence counts only when it
cannot be explained by the teammate leaving our comm range: when the silence reaches
`no_status_s`, the teammate's last heard position, moved by as far as it can travel
in `no_status_s` (max_speed x no_status_s), must still be within our comm range of
where we are now. A teammate heard near the edge of range that drove off is not
silent; one killed well inside range is. The judgement is made once per silence (at
its onset) and kept until the teammate is heard again.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..watchman import NEG

if TYPE_CHECKING:
    from ..domain import UvDomain


def last_heard(dom: "UvDomain", rid: str) -> float:
    r = dom.robots[rid]
    return r.t if r.t != NEG else dom.t0


def _teammates(dom: "UvDomain"):
    """Teammates a robot's EA was hearing (none for the TEAM: it watches all as its own)."""
    if dom.watchman.hears_all:
        return ()
    return [rid for rid in dom.robot_ids if rid not in dom.mine and dom.robots[rid].t != NEG]


def silent_in_range(dom: "UvDomain", rid: str, thr: float) -> bool:
    """Was teammate `rid` close enough, when last heard, that it cannot have driven out of
    our comm range before its silence reached `thr`? Judged once per silence."""
    r = dom.robots[rid]
    if r.silence is not None and r.silence[0] == r.t:
        return r.silence[1]
    me = dom.robots[dom.owner]
    d = math.hypot(r.x - me.x, r.y - me.y)
    ok = d + r.max_speed * thr <= me.comm_range
    r.silence = (r.t, ok)
    return ok


def no_status(dom: "UvDomain", t: float, cands: list) -> None:
    thr = float(dom.uv["no_status_s"])
    for rid in dom.mine_sorted:
        last = last_heard(dom, rid)
        silent = t - last
        if silent >= thr:
            never = dom.robots[rid].t == NEG
            cands.append(_cand(dom, t, rid, last, silent, never, None))
    for rid in _teammates(dom):
        last = dom.robots[rid].t
        silent = t - last
        if silent >= thr and silent_in_range(dom, rid, thr):
            cands.append(_cand(dom, t, rid, last, silent, False, dom.owner))


def _cand(dom: "UvDomain", t: float, rid: str, last: float, silent: float, never: bool, heard_by: str | None):
    text = f"No status from {dom.name(rid)} for {silent:.0f} s" + (" (never reported)" if never else "")
    if heard_by is not None:
        text += " (a teammate within comm range)"
    details = {"robot": rid, "last_state_t": None if never else last, "silent_s": round(silent, 1)}
    if heard_by is not None:
        details["teammate"] = True
    return dom.cand(t, "no-status", None, (rid,), text, ("no-status", rid), silent, details)


def wakeup(dom: "UvDomain", now: float) -> float:
    """The next time a watched robot becomes silent for `no_status_s`, or a silent one is
    due a look again (every `no_status_s`, for VOA's progressive repeats)."""
    thr = float(dom.uv["no_status_s"])
    best = math.inf
    judged_out = [rid for rid in _teammates(dom) if dom.robots[rid].silence == (dom.robots[rid].t, False)]
    for rid in (*dom.mine_sorted, *(r for r in _teammates(dom) if r not in judged_out)):
        last = last_heard(dom, rid)
        due = last + thr
        if due <= now:
            due = last + thr * (math.floor((now - last) / thr) + 1)
        best = min(best, due)
    return best
