"""Progress toward a basic action (paper 7.3, 7.5): at-goal, stuck, divergent.

Each robot keeps an event history on its `Robot` record: where it last moved from
(stuck) and its best distance to the current waypoint since the last progress
check (divergent). Subtleties: a robot paused or waiting for GPS is not stuck; a
turning robot is neither stuck nor divergent until its turn could have completed
(heading error / turn rate, plus `turn_settle_s`); the divergent threshold grows with
expected speed.

A turn restarts the stuck clock where it could have completed, as a pause does where
it ends: a robot that turns in place for the whole stuck interval and then drives off
is not stuck, one that stays put after its turn is, `stuck_s` after the turn could have
completed. A turn is known from the heading error to the goto's waypoint, or seen: a
robot in place whose heading moved more than `turn_tolerance_deg` from the one it
stopped with, within `stuck_s` of stopping, is turning in place (at most half a turn
from there, so it could have completed by now + (180 - turned) / turn rate + settle).
A heading turned only after that, or never by more than the tolerance (jitter), does
not hold the clock back: a robot really stuck is still told, late by one turn at most.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..render import m_
from ..watchman import NEG, Robot

if TYPE_CHECKING:
    from ..domain import UvDomain


def heading_error(r: Robot, gx: float, gy: float) -> float:
    """Degrees between the robot's compass heading and the bearing to (gx, gy)."""
    bearing = math.degrees(math.atan2(gx - r.x, gy - r.y)) % 360.0
    return abs((bearing - r.heading + 180.0) % 360.0 - 180.0)


def turned(a: float, b: float) -> float:
    """Degrees between two compass headings (0..180)."""
    return abs((a - b + 180.0) % 360.0 - 180.0)


def track(dom: "UvDomain", t: float) -> None:
    """Update the stuck anchor and turn state of every robot heard this epoch."""
    uv = dom.uv
    stuck_m, stuck_s = float(uv["stuck_m"]), float(uv["stuck_s"])
    tol, settle = float(uv["turn_tolerance_deg"]), float(uv["turn_settle_s"])
    for rid in dom.watchman.dirty:
        r = dom.robots[rid]
        if r.anchor_t == NEG or r.paused_t >= r.anchor_t or math.hypot(r.x - r.anchor_x, r.y - r.anchor_y) > stuck_m:
            # moved (or paused / waiting for GPS): the stuck clock starts again from here
            r.anchor_t, r.anchor_x, r.anchor_y, r.anchor_h = max(r.t, r.paused_t), r.x, r.y, r.heading
        elif r.t - r.anchor_t < stuck_s:
            done = turned(r.heading, r.anchor_h)
            if done > tol:   # turning in place: at most half a turn from where it stopped
                r.spin_until = max(r.spin_until, r.t + (180.0 - done) / r.turn_rate + settle)


def at_goal(dom: "UvDomain", t: float, cands: list) -> None:
    """A robot within its goto waypoint's radius: report it and end the goto.

    A robot's controller decides it arrived on its true position and reports
    `success` at once, usually just before the state that shows it inside the radius
    (docs/uv-domain.md; sim.py `RobotSim._recipe`). So a goto whose success was heard this epoch
    is judged on the latest state (allowing twice the reported GPS error), before the
    report ends it (`UvDomain.report_end`)."""
    dirty = dom.watchman.dirty
    reported = dom.reported
    for mid, (m, place) in list(dom.goal_missions.items()):
        done = reported.get(mid)
        if (m.unit not in dirty and done is None) or not dom.active(mid):
            continue
        r = dom.robots[m.unit]
        if r.t == NEG:
            continue
        gx, gy, rad = dom.goals[place]
        d = math.hypot(r.x - gx, r.y - gy)
        if done is not None and done[1] == "success":
            rad += 2.0 * r.sigma
        if d > rad:
            continue
        if m.unit in dom.mine:
            cands.append(dom.cand(r.t, "at-goal", m, (m.unit,), f"{dom.name(m.unit)} at goal {place} ({m_(d)} away)",
                                  ("at-goal", mid), None, {"mission": mid, "place": place, "places": [place],
                                                           "distance_m": round(d, 1)}))
        reported.pop(mid, None)
        dom.end_mission(m, r.t if done is None else min(r.t, done[0]))


def stuck(dom: "UvDomain", t: float, cands: list) -> None:
    """Moved less than stuck_m in stuck_s while a moving task is active, not at its
    goal and in `moving` mode, counted from when its last turn could have completed."""
    stuck_s = float(dom.uv["stuck_s"])
    fresh = float(dom.uv["no_status_s"])
    for rid, m in dom.moving_tasks().items():
        r = dom.robots[rid]
        if r.t == NEG or r.mode != "moving" or t - r.t > fresh:
            continue   # silent robots are no-status, paused ones are waiting
        # the stuck clock: from the task's start, the robot's last move, or where its turn could have completed
        turn = r.turn_until if r.turn_until > r.spin_until else r.spin_until
        still = t - max(r.anchor_t, dom.started_at(m), turn)
        if still < stuck_s:
            continue
        goal = m.goal()
        if goal is not None:
            gx, gy, rad = dom.goals[goal]
            if math.hypot(r.x - gx, r.y - gy) <= rad:
                continue
        cands.append(dom.cand(t, "stuck", m, (rid,), f"{dom.name(rid)} stuck for {still:.0f} s during {m.TYPE} "
                              f"(moved less than {m_(float(dom.uv['stuck_m']))})", ("stuck", rid), still,
                              {"mission": m.id, "still_s": round(still, 1), "x": round(r.x, 1), "y": round(r.y, 1)}))


def divergent(dom: "UvDomain", t: float, cands: list) -> None:
    """Distance to the current waypoint grew by more than base + k x expected speed
    since the best distance at the last progress check."""
    uv = dom.uv
    base, k = float(uv["divergent_base_m"]), float(uv["divergent_speed_s"])
    tol, settle = float(uv["turn_tolerance_deg"]), float(uv["turn_settle_s"])
    dirty = dom.watchman.dirty
    for mid, (m, place) in dom.goal_missions.items():
        rid = m.unit
        if rid not in dirty or rid not in dom.mine or not dom.active(mid):
            continue
        r = dom.robots[rid]
        gx, gy, _ = dom.goals[place]
        d = math.hypot(r.x - gx, r.y - gy)
        err = heading_error(r, gx, gy)
        if r.ref_goal != mid:   # a new waypoint: a new history
            r.ref_goal, r.ref_d, r.ref_t, r.aligned = mid, d, r.t, True
            r.turn_until = NEG
        if err > tol and r.aligned:    # a turn begins: allow the time it needs
            r.turn_until = r.t + err / r.turn_rate + settle
        r.aligned = err <= tol
        if r.t < r.turn_until or d < r.ref_d or r.mode != "moving":
            r.ref_d, r.ref_t = min(d, r.ref_d) if r.t >= r.turn_until else d, r.t
            continue
        grown = d - r.ref_d
        expected = float(m.params.get("speed_mps", r.max_speed))
        thr = base + k * expected
        if grown > thr:
            cands.append(dom.cand(t, "divergent", m, (rid,), f"{dom.name(rid)} diverging from {place}: "
                                  f"{m_(grown)} farther than at {r.ref_t:.0f} s (now {m_(d)} away)",
                                  ("divergent", mid), grown,
                                  {"mission": mid, "place": place, "places": [place], "distance_m": round(d, 1),
                                   "grown_m": round(grown, 1), "threshold_m": round(thr, 1)}))
