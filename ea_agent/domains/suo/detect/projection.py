"""Constraint violations projected (Fig. 1's category; beyond the paper's EA): before a
unit leaves its route or axis, or arrives after its mission's END-NLT, from how it has
been moving.

A projection is worth its name only ahead of what it projects: one is raised only when
the model puts the violation at least `[voi] projection_min_lead_s` ahead (less, and
the actual alert is due within about a report interval: a late alert with a misleading
name).

A route departure is projected from the unit's recent trend against its route: its
cross-track rate, from the heading of its members' latest reports against the route's
direction, confirmed by the growth of its reported distance off the route. Only once the
picture has settled: every member heard recently shows the drift (while some have not
reported since the unit turned, the mean heading and the centroid lag the unit, and a
projection made then comes after the fact). A unit that cannot be projected that far
ahead (it leaves faster than its reports can tell) is told by the actual alert alone.

Why not straight-line extrapolation of the position: a unit that follows a bending
route would be projected off it at every bend. What is extrapolated is the measure the
actual alert judges (the distance off the route: at this rate it crosses the threshold
at ...; the distance still to go to the destination: at this rate it arrives at ...), and
a drift counts only where the members' own reports move away from the route (dead
reckoning carries a unit on along its old heading past a bend it has taken, or past the
route it came back to). A projection and the later actual alert are one story for VOA:
the projection sets the history of the actual alert's key, so the actual violation is
not told again unless it is much worse (the type's repeat ratio)."""
from __future__ import annotations

import math
from collections import deque

import numpy as np
import shapely

from ea_agent.core.alert import Candidate, hms

from ..missions import Mission
from ..render import km
from .base import Changes, Detector

KEEP_S = 300.0   # history kept per mission
SAMPLE_S = 10.0  # scenario seconds between samples of the trends
MARGIN = 2.0     # a late arrival is projected only this many schedule thresholds late
CONFIRM_S = 30.0  # a route departure's heading is confirmed by the distance off the route over this much history
CONFIRM = 0.5     # ... grown at least this share of the rate the heading gives
AGREE = 0.5       # the picture has settled when every member heard recently drifts at least this share of the mean
MIN_RATE = 0.1    # m/s: a slower cross-track drift is noise (150 m would take 25 min)
STEP_M = 5.0      # a route's direction is taken over this much of it


class Projections(Detector):
    TYPES = {"projected-out-of-position": "constraint-violation-projected",
             "projected-late": "constraint-violation-projected"}

    def reset(self) -> None:
        self.hist: dict[str, deque] = {}   # mission -> (t, distance off its route, to go, reported centroid)
        self.next_t = -1.0   # the next sample's time; none yet: the first grid time from the next look
        self.due: list[Mission] = []
        self.routes: dict[str, tuple] = {}      # mission -> (its monitor list, its length, _route of it)
        self.beyond: dict[tuple, tuple] = {}    # (route, destination) -> (line, area, length, end to area)
        self.active: tuple | None = None        # (plan states, their version, the active mission ids)
        self.plans: tuple | None = None         # (what they were built from, _Plans of the watched missions)

    def observe(self, t: float, ch: Changes) -> None:
        """Every SAMPLE_S of scenario time (a trend over minutes needs no finer samples),
        each active mission's distance off its route and still to go, from its members'
        positions dead-reckoned to now (a stale report alone would make it seem behind),
        and the centroid of their last reports (what confirms a drift: dead reckoning
        carries a unit on past where it stopped)."""
        dom = self.dom
        self.due = []
        if dom.plan is None or float(dom.voi_cfg["projection_horizon_s"]) <= 0.0:
            return
        # samples fall on a grid of scenario time, not SAMPLE_S after whichever epoch was
        # closed: an EA that hears more messages closes more epochs, and every EA must
        # sample at the same moments
        if self.next_t < 0.0:
            self.next_t = math.ceil(t / SAMPLE_S) * SAMPLE_S
        if t < self.next_t or not ch.rescan:   # at a scan's epoch, which every EA closes, whatever
            return                              # epoch_s and unknown_scan_s are
        self.next_t = (math.floor(t / SAMPLE_S) + 1) * SAMPLE_S
        plans = self._plans()
        self.due = plans.due
        rows = []   # (index in due, its history, where it is now)
        for i, m in enumerate(self.due):
            pos = dom.unit_now.get(m.unit)   # where reports up to a minute old put it now (dead-reckoned)
            if pos is None:
                continue
            h = self.hist.get(m.id)
            if h is None:
                h = self.hist[m.id] = deque()
            elif h and h[-1][0] >= t:
                continue
            rows.append((i, h, pos))
        if not rows:
            return
        if len(rows) == len(self.due):
            measured = plans.measure([pos for _, _, pos in rows])
        else:
            measured = self._measure([self.due[i] for i, _, _ in rows], [pos for _, _, pos in rows])
        old = t - KEEP_S
        unit_pos = dom.unit_pos
        for (i, h, _), off, to_go in zip(rows, *measured):
            h.append((t, off, to_go, unit_pos.get(self.due[i].unit)))
            while h and h[0][0] < old:
                h.popleft()

    def _plans(self) -> "_Plans":
        """The watched missions and how each is measured, kept until a plan state, the
        organization or a location monitor changes (the same scan of every active mission
        at every sample otherwise)."""
        dom = self.dom
        state = dom.plan.state
        version = getattr(state, "version", None)
        loc = dom.location
        c = self.plans
        if (c is not None and version is not None and c[0] is dom.plan and c[1] is state and c[2] == version
                and c[3] is dom.own_units and c[4] == loc._rev and c[5] is dom.missions):
            return c[6]
        due = self._watched()
        plans = _Plans(due, *self._how(due))
        self.plans = (dom.plan, state, version, dom.own_units, loc._rev, dom.missions, plans)
        return plans

    def _measure(self, ms: list[Mission], where: list) -> tuple[list, list]:
        """Each mission's distance off its route (None without one) and still to go (along its
        route, then on to its destination; None without a destination and a deadline), with
        one vectorised GEOS call per kind of measure for all of them (per-call overhead is
        most of the cost for a few missions)."""
        return _Plans(ms, *self._how(ms)).measure(where)

    def _how(self, ms: list[Mission]) -> tuple[list, list]:
        """How _measure measures the missions: plain distances from the position (index, to
        which list, geometry) and along a route (index, its line, the route's length and its
        end's distance to the destination)."""
        dom = self.dom
        dist = []
        along = []
        for i, m in enumerate(ms):
            r = self._route(m)
            if r is not None:
                dist.append((i, "off", self._line(r)))
            dest = self._destination(m)
            if dest is None:
                continue
            if r is not None and r[1] != "corridor":   # along the route, then on to the destination
                line = dom.overlay[r[0]].geom
                along.append((i, line, self._beyond(r[0], line, dest)))
            else:
                dist.append((i, "to_go", dom.overlay[dest].area))
        return dist, along

    def _beyond(self, rid: str, line, dest: str) -> tuple[float, float]:
        """A route's length and the distance from its end to the destination (fixed per pair)."""
        area = self.dom.overlay[dest].area
        c = self.beyond.get((rid, dest))
        if c is None or c[0] is not line or c[1] is not area:
            c = (line, area, line.length, float(shapely.distance(area, shapely.Point(line.coords[-1]))))
            self.beyond[rid, dest] = c
        return c[2], c[3]

    def _watched(self) -> list[Mission]:
        """Active missions of ours that have a route or axis, or a destination and a deadline."""
        dom = self.dom
        out = []
        for mid in self._active():
            m = dom.missions.get(mid)
            if m is not None and dom.in_plan(m) and (self._route(m) is not None or self._destination(m) is not None):
                out.append(m)
        return out

    def _active(self) -> list[str]:
        """The active missions' ids in plan-state order, kept until a plan state changes
        (the state dict counts its changes) rather than scanning every mission per sample."""
        state = self.dom.plan.state
        version = getattr(state, "version", None)
        c = self.active
        if version is None or c is None or c[0] is not state or c[1] != version:
            c = self.active = (state, version, [mid for mid, s in state.items() if s == "active"])
        return c[2]

    def _route(self, m: Mission) -> tuple[str, str] | None:
        """The route or axis whose centroid monitor the mission posted (geometry id, which);
        remembered while the mission's monitor list is the same list of the same length
        (monitors are only ever appended to it)."""
        mons = self.dom.location.monitors.get(m.id, ())
        c = self.routes.get(m.id)
        if c is not None and c[0] is mons and c[1] == len(mons):
            return c[2]
        r = None
        for _, geom, rule, what in mons:
            if what in ("route", "axis") and rule == "centroid":   # a corridor's trend is too weak to project
                r = geom, what
                break
        self.routes[m.id] = (mons, len(mons), r)
        return r

    def _line(self, r: tuple[str, str]):
        return self.dom.location.corridors[r[0]] if r[1] == "corridor" else self.dom.overlay[r[0]].geom

    def _destination(self, m: Mission) -> str | None:
        dest = m.params.get("destination") or m.params.get("objective")
        end = m.spec.end
        if dest not in self.dom.overlay or end.type not in ("END-NLT", "END-AT") or end.t is None:
            return None
        return dest

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if dom.plan is None:
            return
        horizon = float(dom.voi_cfg["projection_horizon_s"])
        span = float(dom.voi_cfg["projection_trend_s"])
        for m in self.due:   # sampled this epoch
            h = self.hist.get(m.id)
            if not h or h[-1][0] < t:
                continue
            min_lead = self.dom.voi(m, "projection_min_lead_s")
            self._off_route_ahead(m, t, h, horizon, min_lead, cands)
            old = h[0] if h[0][0] <= t - span else None   # samples are in time order
            if old is not None and h[-1][0] > old[0]:
                self._late_ahead(m, t, old, h[-1], h[-1][0] - old[0], horizon, min_lead, cands)

    def _off_route_ahead(self, m, t, h, horizon, min_lead, cands) -> None:
        """A unit drifting off its route, projected from its cross-track rate (see the module
        note): raised when it would cross the threshold in min_lead..horizon."""
        now = h[-1]
        d1 = now[1]
        if d1 is None:
            return
        thr = self.dom.voi(m, "out_of_position_m")
        if d1 >= thr:
            return   # already out: the actual alert's business
        prev = None   # the latest sample at least CONFIRM_S old
        for x in h:
            if x[0] > t - CONFIRM_S:
                break
            prev = x
        if prev is None or prev[1] is None or prev[3] is None or now[3] is None:
            return
        dt = now[0] - prev[0]
        if (d1 - prev[1]) / dt <= MIN_RATE:   # not drifting away (checked first: the rest costs more)
            return
        drift = self._drift(m, t)
        if drift is None:
            return
        heading_rate, fastest, settled, members = drift
        if not settled or heading_rate <= MIN_RATE:
            return   # the picture lags the unit (some members still show how it went before)
        # confirmed by the reports themselves: dead reckoning carries a unit that has
        # stopped drifting (back on its route) on past it until each member reports again
        line = self._line(self._route(m))
        grown = (float(line.distance(shapely.Point(now[3]))) - float(line.distance(shapely.Point(prev[3])))) / dt
        if grown < CONFIRM * heading_rate:
            return
        # the fastest reading: a member's report straddling the turn shows part of the
        # drift, so the mean can still lag; a projection errs early, never late
        rate = max(heading_rate, fastest, grown)
        ahead = (thr - d1) / rate
        if ahead < min_lead or ahead > horizon:
            return
        geom, what = self._route(m)
        name = self.dom.name(m.unit)
        cands.append(Candidate(
            t, "projected-out-of-position", m.compute_priority("projected-out-of-position"), (m.unit,),
            f"{name} projected to leave {geom} in {ahead:.0f} s (at {hms(t + ahead)}): {km(d1)} off it now, "
            f"drifting {rate:.1f} m/s",
            key=("projected-out-of-position", m.id, what), measure=horizon - ahead,
            details={"mission": m.id, "projects": "out-of-position", "control_measure": geom, "check": what,
                     "projected_t": round(t + ahead, 1),
                     "lead_s": round(ahead, 1), "distance_m": round(d1, 1), "rate_mps": round(rate, 2),
                     "heading_rate_mps": round(heading_rate, 2), "trend_rate_mps": round(grown, 2),
                     "members": members, "min_lead_s": min_lead,
                     "threshold_m": thr, "places": [geom]},
            also=((("out-of-position", m.id, what), thr),), projection=True))

    def _drift(self, m: Mission, t: float) -> tuple[float, float, bool, int] | None:
        """The unit's cross-track rate away from its route (m/s): the mean of the velocities
        its members' latest reports showed (none for one that showed it standing still)
        across the route's direction at its nearest point, and the fastest member's;
        whether the picture has settled (every member heard within unknown_position_s
        drifts at least AGREE of the mean: none still shows the heading it had before the
        unit turned); how many members were judged. None without members heard or a
        position. (At a bend, a unit that follows the route is dead-reckoned past it on its
        old heading until its members report again, every member agreeing: what its reports
        themselves show, in _off_route_ahead, tells the two apart.)"""
        dom = self.dom
        pos = dom.unit_now.get(m.unit)
        pic = dom.pic
        idx = pic.members.get(m.unit)
        if pos is None or idx is None or not len(idx):
            return None
        seen = pic.seen[idx]
        heard = ~np.isnan(pic.xy[idx, 0]) & (t - seen <= float(dom.voi_cfg["unknown_position_s"]))
        if not heard.any():
            return None
        idx, seen = idx[heard], seen[heard]
        vel = pic.vel[idx].copy()
        vel[seen > pic.moved_t[idx] + 0.5] = 0.0   # its last report showed it standing still
        line = self._line(self._route(m))
        s = float(line.project(shapely.Point(pos)))
        near = line.interpolate(s)
        a = line.interpolate(max(0.0, s - STEP_M))
        b = line.interpolate(min(line.length, s + STEP_M))
        tx, ty = b.x - a.x, b.y - a.y
        n = math.hypot(tx, ty)
        if n <= 0.0:
            return None
        nx, ny = -ty / n, tx / n   # normal to the route there, turned to the unit's side
        side = nx * (pos[0] - near.x) + ny * (pos[1] - near.y)
        if abs(side) < 1.0:   # on the route: the side it heads to
            mean = vel.mean(axis=0)
            side = nx * mean[0] + ny * mean[1]
        if side < 0.0:
            nx, ny = -nx, -ny
        w = vel @ np.array((nx, ny))
        rate = float(w.mean())
        settled = rate > 0.0 and float(w.min()) >= AGREE * rate
        return rate, float(w.max()), settled, int(len(idx))

    def _late_ahead(self, m, t, old, now, dt, horizon, min_lead, cands) -> None:
        g0, g1 = old[2], now[2]
        if g0 is None or g1 is None:
            return
        end = m.spec.end.t
        if end - t > horizon:
            return   # the deadline too far to judge by a trend
        dom = self.dom
        thr_m, thr_s = dom.voi(m, "out_of_position_m"), dom.voi(m, "schedule_s")
        lead = end + thr_s - t   # the actual late alert is due at end + schedule_s
        if g1 <= thr_m or lead <= 0.0 or lead < min_lead:
            return   # there already, or the violation too near to be worth a projection
        closing = (g0 - g1) / dt
        eta = t + g1 / closing if closing > 0.05 else math.inf
        late = eta - end
        if late <= MARGIN * thr_s:   # a clear miss: the trend is a noisy guess of the arrival
            return
        dest = self._destination(m)
        when = "never at this rate" if math.isinf(eta) else f"at {hms(eta)}, {late:.0f} s late"
        cands.append(Candidate(
            t, "projected-late", m.compute_priority("projected-late"), (m.unit,),
            f"{dom.name(m.unit)} projected to reach {dest} {when} (NLT {hms(end)}): {km(g1)} to go at "
            f"{max(closing, 0.0):.1f} m/s",
            key=("projected-late", m.id), measure=min(late, 86400.0),
            details={"mission": m.id, "projects": "schedule", "control_measure": dest,
                     "projected_t": None if math.isinf(eta) else round(eta, 1),
                     "nlt_t": end, "late_s": None if math.isinf(late) else round(late, 1), "to_go_m": round(g1, 1),
                     "closing_mps": round(closing, 2), "threshold_s": thr_s, "places": [dest]},
            also=((("schedule", m.id, "end"), thr_s),), projection=True))


_NAN_ALLOW = np.intc(0)   # shapely.lib.points' handle_nan: allow (shapely.points' default)


class _Plans:
    """How a list of missions is measured (Projections._how), with the index and geometry
    arrays of its vectorised GEOS calls built once, called straight on shapely.lib (the
    wrappers' overhead is a good part of a call on a few points)."""

    def __init__(self, due: list[Mission], dist: list, along: list):
        self.due = due
        self.dist = [(i, which == "off") for i, which, _ in dist]
        self.dist_idx = np.array([i for i, _, _ in dist], dtype=np.intp)
        self.dist_geoms = np.array([g for _, _, g in dist], dtype=object)
        self.along = [(i, length, rest) for i, _, (length, rest) in along]
        self.along_idx = np.array([i for i, _, _ in along], dtype=np.intp)
        self.along_lines = np.array([line for _, line, _ in along], dtype=object)

    def measure(self, where: list) -> tuple[list, list]:
        """Projections._measure of the missions at `where` (one position per mission)."""
        n = len(where)
        off: list[float | None] = [None] * n
        to_go: list[float | None] = [None] * n
        pts = shapely.lib.points(np.array(where, dtype=float), _NAN_ALLOW)
        if self.dist:
            ds = shapely.lib.distance(self.dist_geoms, pts[self.dist_idx]).tolist()
            for (i, is_off), d in zip(self.dist, ds):
                (off if is_off else to_go)[i] = d
        if self.along:
            at = shapely.lib.line_locate_point(self.along_lines, pts[self.along_idx]).tolist()
            for (i, length, rest), x in zip(self.along, at):
                to_go[i] = length - x + rest
        return off, to_go
