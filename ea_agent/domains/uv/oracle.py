"""Ground truth for a UV scenario from the simulator's TRUE state, written apart from
the detectors (it never reads their code or their output).

Per EA owner it says:
 - incidents: what a demanding operator (TEAM) or a robot's controller must be told,
   by an alert of an accepted type, inside [t0, t1], about one of the subjects;
 - situations: when an alert of a type is justified at all (a real situation exists),
   so that an alert outside every situation and incident counts as unwanted.
Windows start at the true onset and are generous; thresholds come from configs/uv.toml
(the user's statement of what is worth knowing), else the spec's defaults.
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
from shapely.geometry import LineString, Point

from .sim import DT

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "uv.toml"
DEFAULTS = {"no_status_s": 5.0, "stuck_s": 10.0, "stuck_m": 1.0, "divergent_base_m": 3.0, "divergent_speed_s": 3.0,
            "lost_s": 3.0, "lost_human_s": 20.0, "drop_s": 30.0, "collision_m": 1.0, "collision_horizon_s": 5.0}


def thresholds(path: Path = CONFIG) -> dict[str, float]:
    """The [uv] thresholds the EAs use (the spec's defaults when the file is absent)."""
    out = dict(DEFAULTS)
    if path.exists():
        uv = tomllib.loads(path.read_text()).get("uv", {})
        out.update({k: float(uv[k]) for k in DEFAULTS if isinstance(uv.get(k), (int, float))})
    return out


def runs(mask: np.ndarray, times: np.ndarray) -> list[tuple[float, float]]:
    """[(first, last)] times of the True runs of `mask`."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return [(float(times[a]), float(times[b - 1])) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1))]


class Truth:
    def __init__(self, sim, owners: list[str], thr: dict[str, float]):
        self.sim, self.owners, self.thr = sim, owners, thr
        self.t = sim.times
        self.robots = list(sim.robots)
        self.attrs = {r: sim.robots[r].attrs for r in self.robots}
        self.vis = {k: v & sim.link[k[0]] for k, v in sim.visible.items()}   # what a robot can report
        self.incidents: list[dict] = []
        self.situations: list[dict] = []

    # -- recording -------------------------------------------------------------------------
    def must(self, owner: str, typ: str, subjects: list[str], t0: float, t1: float, label: str) -> None:
        if owner in self.owners:
            self.incidents.append({"owner": owner, "type": typ, "accept": [typ], "subjects": sorted(set(subjects)),
                                   "t0": round(max(0.0, t0), 1), "t1": round(t1, 1), "label": label})

    def may(self, owner: str, typ: str, subjects: list[str], t0: float, t1: float) -> None:
        if owner in self.owners:
            self.situations.append({"owner": owner, "accept": [typ], "subjects": sorted(set(subjects)),
                                    "t0": round(max(0.0, t0), 1), "t1": round(t1, 1)})

    def everyone(self, typ: str, subjects: list[str], t0: float, t1: float) -> None:
        for o in self.owners:
            self.may(o, typ, subjects, t0, t1)

    def idx(self, t: float) -> int:
        return min(len(self.t) - 1, max(0, int(round(t / DT))))

    def dist(self, a: str, b: str, i: int) -> float:
        return float(np.hypot(*(self.sim.pos[a][i] - self.sim.pos[b][i])))

    # -- alert types ------------------------------------------------------------------------------
    def no_status(self) -> None:
        thr = self.thr["no_status_s"]
        for x in self.robots:
            for a, b in runs(~self.sim.link[x], self.t):
                last, back = a - DT, b + DT
                if back - last <= thr + 1.0:
                    continue
                onset = last + thr
                self.must("TEAM", "no-status", [x], onset - 1, onset + 20, f"{x} silent {a:.0f}-{back:.0f} s")
                self.everyone("no-status", [x], last, back + 10)
                i = self.idx(last)
                for r in self.robots:
                    if r != x and self.dist(r, x, i) <= 0.9 * self.attrs[r]["comm_range_m"]:
                        self.must(r, "no-status", [x], onset - 1, onset + 20, f"{x} silent, within {r}'s range")
        for r in self.robots:   # a teammate out of comm range is truly unheard
            for x in self.robots:
                if x == r:
                    continue
                d = np.hypot(*(self.sim.pos[x] - self.sim.pos[r]).T)
                for a, b in runs(d > 0.95 * self.attrs[r]["comm_range_m"], self.t):
                    self.may(r, "no-status", [x], a, b + thr + 10)

    def moving(self, r: str, i: int) -> bool:
        return self.sim.task[r][i] is not None and self.sim.mode[r][i] == "moving"

    def stuck(self) -> None:
        ts, tm = self.thr["stuck_s"], self.thr["stuck_m"]
        for kind, r, a, b in self.sim.faults:
            if kind == "stuck":
                self.must("TEAM", "stuck", [r], a, a + ts + 25, f"{r} stuck {a:.0f}-{b:.0f} s")
                self.must(r, "stuck", [r], a, a + ts + 25, f"{r} stuck {a:.0f}-{b:.0f} s")
                self.everyone("stuck", [r], a, b + 10)
        k = int(round(ts / DT))
        for r in self.robots:   # any other true standstill while a moving task is active
            p = self.sim.pos[r]
            mask = np.zeros(len(self.t), bool)
            for i in range(k, len(self.t)):
                if all(self.moving(r, j) for j in range(i - k, i + 1)):
                    mask[i] = np.hypot(*(p[i] - p[i - k])) < 2 * tm
            for a, b in runs(mask, self.t):
                self.everyone("stuck", [r], a - ts, b + 15)

    def at_goal(self) -> None:
        for ev in self.sim.log:
            if ev["what"] == "arrive":
                r, t = ev["robot"], ev["t"]
                self.must(r, "at-goal", [r, ev["waypoint"]], t - 1, t + 10, f"{r} at {ev['waypoint']}")
                self.everyone("at-goal", [r, ev["waypoint"]], t - 2, t + 30)

    def divergent(self) -> None:
        for kind, r, a, b in self.sim.faults:
            if kind != "diverge":
                continue
            i0, i1 = self.idx(a), self.idx(b)
            wp = self.sim.goal[r][i0]
            d = self._goal_dist(r, wp)
            onset = next(float(self.t[i]) for i in range(i0 + 1, i1) if d[i] > d[i - 1])
            self.must(r, "divergent", [r, wp], onset, onset + 40, f"{r} drives away from {wp}")
            self.everyone("divergent", [r, wp], a, b + 20)
        for r in self.robots:   # any true growth of the distance to the waypoint outside a turn
            goal = self.sim.goal[r]
            mask = np.zeros(len(self.t), bool)
            start, exempt = 0, 0.0
            for i in range(1, len(self.t)):
                if goal[i] is None:
                    continue
                if goal[i] != goal[i - 1]:
                    start, exempt = i, self._turn_s(r, i)
                d = self._goal_dist(r, goal[i], i - min(i - start, 20), i + 1)
                if self.t[i] - self.t[start] > exempt and d[-1] > d[-2] + 0.05 and d[-1] - d.min() > 3.0:
                    mask[i] = True
            for a, b in runs(mask, self.t):
                self.everyone("divergent", [r, goal[self.idx(a)]], a - 2, b + 15)

    def _goal_dist(self, r: str, wp: str, i0: int = 0, i1: int | None = None) -> np.ndarray:
        c = np.array(self.sim.world[wp].geom.coords[0])
        return np.hypot(*(self.sim.pos[r][i0:i1] - c).T)

    def _turn_s(self, r: str, i: int) -> float:
        """How long the turn toward a new waypoint takes (heading error / turn rate), plus slack."""
        c = np.array(self.sim.world[self.sim.goal[r][i]].geom.coords[0]) - self.sim.pos[r][i]
        v = self.sim.vel[r][i - 1]
        err = abs(math.degrees(math.atan2(v[0] * c[1] - v[1] * c[0], v @ c))) if np.hypot(*v) > 0.1 else 180.0
        return err / self.attrs[r]["turn_rate_dps"] + 3.0

    def targets(self) -> None:
        ls, lh = self.thr["lost_s"], self.thr["lost_human_s"]
        evaders = sorted({e for _, e in self.vis})
        for e in evaders:
            anyv = np.any([self.vis[(r, e)] for r in self.robots], axis=0)
            prev = -math.inf
            for a, b in runs(anyv, self.t):   # the team sees it: first time, or again after a long loss
                if a - prev > lh:
                    who = [r for r in self.robots if self.vis[(r, e)][self.idx(a)]]
                    self.must("TEAM", "target-visible", [e, *who], a - 1, a + 15,
                              f"{e} sighted by {', '.join(who)}" + ("" if prev < 0 else " again"))
                prev = b
            for r in self.robots:
                prev = -math.inf
                for a, b in runs(self.vis[(r, e)], self.t):
                    if a - prev > ls:
                        self.everyone("target-visible", [e, r], a - 1, a + 15)
                    if a - prev > lh and not self._heard(r, e, a):
                        self.must(r, "target-visible", [r, e], a - 1, a + 15, f"{r} sights {e}")
                    prev = b
        self._pursuits()

    def _heard(self, r: str, e: str, t: float) -> bool:
        """Did a teammate within r's comm range see e in the 10 s before t?"""
        i0, i = self.idx(t - 10), self.idx(t)
        rng = self.attrs[r]["comm_range_m"]
        return any(self.vis[(q, e)][i0:i].any() and self.dist(q, r, i) <= rng for q in self.robots if q != r)

    def _pursuits(self) -> None:
        ls, lh = self.thr["lost_s"], self.thr["lost_human_s"]
        log = self.sim.log
        for n, c in enumerate(log):
            if c["what"] != "commit":
                continue
            r, e = c["robot"], c["target"]
            end = next((d for d in log[n + 1:] if d["what"] == "drop" and d["robot"] == r and d["target"] == e), None)
            c0, c1 = c["t"], (end["t"] if end else float(self.t[-1]))
            i0, i1 = self.idx(c0), self.idx(c1)
            own = self.vis[(r, e)][i0:i1 + 1]
            anyv = np.any([self.vis[(q, e)][i0:i1 + 1] for q in self.robots], axis=0)
            tt = self.t[i0:i1 + 1]
            for a, b in runs(~own, tt):
                g = a - DT if a > c0 else c0          # last own sighting (or the commitment)
                stop = b + DT if b < c1 else c1
                seen = tt[(tt <= stop) & anyv]
                g_any = max(g, float(seen.max())) if len(seen) else g
                if stop - g > ls + 1.0:
                    self.must(r, "lost-target", [r, e], g + ls - 1, g_any + ls + 20, f"{r} loses {e}")
                if stop - g > lh + 1.0:
                    self.must("TEAM", "lost-target", [r, e], g + ls - 1, g_any + lh + 25, f"{r} loses {e}")
                if stop - g > ls - 1.0:
                    self.everyone("lost-target", [r, e], g, stop + 30)
            self.everyone("lost-target", [r, e], c1, c1 + 40)   # the EA may keep the pursuit a little longer
        for ev in log + self._gone_at_drop():
            if ev["what"] == "gone":
                r, e, t = ev["robot"], ev["target"], ev["t"]
                self.must("TEAM", "target-gone", [r, e, ev["sector"]], t - 5, t + 20, f"{e} leaves {ev['sector']}")
                self.everyone("target-gone", [r, e, ev["sector"]], t - 10, t + 40)
            elif ev["what"] == "handoff":
                r, q, e, t = ev["robot"], ev["to"], ev["target"], ev["t"]
                if ev.get("accept_t") is not None:   # a handoff is one the teammate took
                    self.must("TEAM", "handoff", [r, q, e], t - 1, ev["accept_t"] + 20, f"{r} hands {e} to {q}")
                self.everyone("handoff", [r, q, e], t - 1, t + 40)

    def _gone_at_drop(self) -> list[dict]:
        """The true exit of a target whose pursuit its EA dropped as gone before the pursuer
        saw it truly outside (a sighting's noise at the sector's edge): the first time, from
        5 s before the drop to 10 s after, the target is truly outside the sector. None in
        that window: the EA's call is not backed by the truth (no incident)."""
        out, log = [], self.sim.log
        for n, c in enumerate(log):
            if c["what"] != "commit":
                continue
            r, e, sec = c["robot"], c["target"], c["sector"]
            end = next((d for d in log[n + 1:] if d["what"] == "drop" and d["robot"] == r and d["target"] == e), None)
            if end is None or end.get("why") != "gone" or sec not in self.sim.world:
                continue
            if any(g["what"] == "gone" and g["robot"] == r and g["target"] == e and c["t"] <= g["t"] <= end["t"]
                   for g in log):
                continue
            geom = self.sim.world[sec].geom
            for i in range(self.idx(end["t"] - 5), self.idx(end["t"] + 10) + 1):
                if not geom.contains(Point(self.sim.ev_pos[e][i])):
                    out.append({"t": float(self.t[i]), "what": "gone", "robot": r, "target": e, "sector": sec})
                    break
        return out

    def collision(self) -> None:
        h, cm = self.thr["collision_horizon_s"], self.thr["collision_m"]
        k = int(round(h / DT))
        for n, a in enumerate(self.robots):
            for b in self.robots[n + 1:]:
                p = self.sim.pos[a] - self.sim.pos[b]
                v = self.sim.vel[a] - self.sim.vel[b]
                vv = np.maximum((v * v).sum(1), 1e-9)
                tc = np.clip(-(p * v).sum(1) / vv, 0.0, h)
                radii = self.attrs[a]["radius_m"] + self.attrs[b]["radius_m"]
                clear = np.hypot(*(p + v * tc[:, None]).T) - radii
                actual = np.hypot(*(p + v * np.minimum(tc, DT)[:, None]).T) - radii   # true, within each step
                for t0, t1 in runs(clear < cm + 4.0, self.t):
                    self.everyone("collision", [a, b], t0 - 2, t1 + h + 2)
                if self.sim.robots[a].kind != self.sim.robots[b].kind:
                    continue     # a UAV flies above a UGV: only a projected risk, never an incident
                for t0, t1 in runs(clear < cm, self.t):
                    i0 = self.idx(t0)
                    j = i0 + int(np.argmin(actual[i0:i0 + k + 1]))
                    if t1 - t0 >= 1.0 and actual[j] < cm:
                        for o in ("TEAM", a, b):
                            self.must(o, "collision", [a, b], t0 - 2, float(self.t[j]) + 2,
                                      f"{a} and {b} pass {actual[j] + radii:.1f} m apart")
        obst = self.sim.obstacles
        for r in self.robots:
            if self.sim.robots[r].kind != "ugv":
                continue
            p, v = self.sim.pos[r], self.sim.vel[r]
            mask = np.array([obst.distance(LineString([p[i], p[i] + v[i] * h])) if np.hypot(*v[i]) > 0.05
                             else obst.distance(Point(p[i])) for i in range(len(self.t))])
            for t0, t1 in runs(mask - self.attrs[r]["radius_m"] < cm + 2.0, self.t):
                self.everyone("collision", [r], t0 - 2, t1 + h + 2)


def ground_truth(sim, owners: list[str], thr: dict[str, float] | None = None) -> dict:
    """truth.json's content: owners, incidents and situations (format as SUO's)."""
    tr = Truth(sim, owners, thr or thresholds())
    for step in (tr.no_status, tr.stuck, tr.at_goal, tr.divergent, tr.targets, tr.collision):
        step()

    def key(d: dict) -> tuple:
        return d["owner"], d["t0"], d.get("type", d["accept"][0]), d["subjects"]
    return {"owners": owners, "tick_s": DT, "thresholds": tr.thr, "incidents": sorted(tr.incidents, key=key),
            "situations": sorted(tr.situations, key=key)}
