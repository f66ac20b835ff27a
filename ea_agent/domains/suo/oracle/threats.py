"""Ground truth for threats and timing."""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
from shapely.geometry import Point

from .spec import (
    CLOSER, EPISODE_S, FRIENDLY_MPS, MATERIAL, NO_VALUE_S, PROX,
    STRONGER, TICK, TOLERANCE_M, _runs,
)


class Threats:
    """Threats and timing (Fig. 4): fratricide, silent units, schedule and ON-ORDER phases,
    proximity of hostiles, calls for fire near friendly units."""

    def fratricide(self) -> None:
        """The unit-boundary rule (paper 6.7.2); inside the lane of a passage of lines that has
        not ended, the passing unit is where the plan puts it."""
        hits: dict[tuple[str, str, str], list[float]] = defaultdict(list)
        lanes = [(mid, m["unit"], m["params"]["partner"], self.area[m["params"]["lane"]])
                 for mid, m in self.missions.items() if m["type"] == "passage-of-lines" and m["params"].get("lane")]
        for k, t in enumerate(self.ticks):
            par = self.parent_at(t)
            open_lanes = [(self.subtree(p, t), self.subtree(q, t), lane) for mid, p, q, lane in lanes
                          if self.valid[mid][0] <= t < min(self.valid[mid][1], self.ended.get(mid, math.inf))]

            def passing(a, ca, b) -> bool:
                return any(a in sp and b in sq and lane.contains(Point(ca)) for sp, sq, lane in open_lanes)

            def bowner(u):
                while u is not None and not self.units[u].get("boundary"):
                    u = par[u]
                return u
            info = []
            for leaf in self.leaves:
                pts = self.member_points(leaf, k)
                b = bowner(leaf)
                c = pts.mean(axis=0)
                info.append((leaf, c, b, self.area[self.units[b]["boundary"]] if b else None,
                             self.units[leaf].get("weapons_range_m") or self._range(leaf, par)))
            # the pairs within weapons range, in the order of a loop over i < j (a brigade has
            # thousands of pairs of leaves; few are that near)
            cs = np.array([x[1] for x in info])
            rs = np.array([x[4] for x in info], dtype=float)
            d = np.hypot(cs[:, None, 0] - cs[None, :, 0], cs[:, None, 1] - cs[None, :, 1])
            for i, j in zip(*np.nonzero(np.triu(d <= np.maximum(rs[:, None], rs[None, :]), 1))):
                a, ca, ba, pa_, ra = info[i]
                b, cb, bb, pb_, rb = info[j]
                if ba is None or bb is None or bb == ba:
                    continue
                in_own_a = pa_.contains(Point(ca))
                in_own_b = pb_.contains(Point(cb))
                if ((not in_own_a and pb_.contains(Point(ca))) or (not in_own_b and pa_.contains(Point(cb)))
                        or (not in_own_a and not in_own_b)) and not passing(a, ca, b) and not passing(b, cb, a):
                    pla, plb = sorted([self.platoon_of(a, t), self.platoon_of(b, t)])
                    for o in self.owners:
                        st = self.subtree(o, t)
                        if a in st or b in st:
                            hits[(o, pla, plb)].append(t)
        for (o, pla, plb), ts in hits.items():
            for a, b in _runs(ts):
                if b - a >= 30:
                    self.must(o, "fratricide", [], [pla, plb], a - self.slack, a + 60, f"{pla} and {plb}", at=a)
                self.may(o, ["fratricide"], [pla, plb], a - self.slack, b + self.slack)

    def unknown_position(self) -> None:
        thr = float(self.voi["unknown_position_s"])
        rs = self.sim.report_s
        for leaf in self.leaves:
            ents = self.units[leaf]["entities"]
            silent, since = [], {}
            for t in self.ticks:
                last = 0.0
                for e in ents:
                    ph = round(self.sim.report_phase[e], 2)
                    k = math.floor((t - ph) / rs)
                    while k >= 0 and not self.sim.reports_at(e, ph + k * rs):
                        k -= 1
                    if k >= 0:
                        last = max(last, ph + k * rs)
                if t - last > thr:
                    silent.append(t)
                    since.setdefault(last, t)
            for a, b in _runs(silent):
                par = self.parent_at(a)
                # it happened when the silence passed the threshold, between two ticks
                crossed = max((lst + thr for lst, t in since.items() if t == a), default=a)
                for o in self.owners_of(leaf, a):
                    self.must(o, "unknown-position", [], [leaf, par[leaf]], crossed - 1, crossed + 30,
                              f"{leaf} silent", at=crossed)
                    self.may(o, ["unknown-position"], [leaf, par[leaf]], crossed - 1, b + 10)

    def schedule(self) -> None:
        thr_default = float(self.voi["schedule_s"])
        for mid, m in self.missions.items():
            for phase, actual in (("start", self.started.get(mid)), ("end", self.ended.get(mid))):
                tc = m.get(phase)
                if tc and tc["type"] == "ON-ORDER":
                    self._on_order(mid, m, phase, actual)
                if not tc or tc["type"] in ("ASAP", "ON-ORDER"):
                    continue
                thr = float(m["params"].get("voi", {}).get("schedule_s", thr_default))
                when, kind = tc["t"], tc["type"].split("-")[1]
                act = actual if actual is not None else math.inf
                v0, v1 = self.valid[mid]
                if not v0 <= when + thr < v1:   # the plan was changed before it was due
                    continue
                if kind in ("NLT", "AT") and act > when + thr:
                    t = when + thr
                    for o in self.owners_of(m["unit"], t):
                        self.must(o, "schedule", [], [m["unit"]], t - 1, t + 5, f"{mid} {phase} late", at=t)
                        self.may(o, ["schedule"], [m["unit"]], t - 1, min(act, 1e9) + 1)
                if kind in ("NET", "AT") and act < when - thr:
                    for o in self.owners_of(m["unit"], act):
                        self.must(o, "schedule", [], [m["unit"]], act - 1, act + 5, f"{mid} {phase} early", at=act)

    def _on_order(self, mid: str, m: dict, phase: str, actual: float | None) -> None:
        """An ON-ORDER phase comes within the schedule threshold of its superior's order;
        one that comes with no order at all, or well before it, is an incident when it comes."""
        thr = float(m["params"].get("voi", {}).get("schedule_s", self.voi["schedule_s"]))
        order = next((o["t"] for o in getattr(self.sim, "mission_orders", ())
                      if o["mission"] == mid and o["phase"] == phase), None)
        v0, v1 = self.valid[mid]
        if order is not None and (actual is None or actual > order + thr) and v0 <= order + thr < v1:
            t = order + thr
            for o in self.owners_of(m["unit"], t):
                self.must(o, "schedule", [], [m["unit"]], t - 1, t + 5, f"{mid} {phase} late on order", at=t)
                self.may(o, ["schedule"], [m["unit"]], t - 1, min(actual or 1e9, 1e9) + 1)
        elif actual is not None and (order is None or actual < order - thr) and v0 <= actual < v1:
            for o in self.owners_of(m["unit"], actual):
                self.must(o, "schedule", [], [m["unit"]], actual - 1, actual + 5,
                          f"{mid} {phase} without an order", at=actual)
                if order is not None:   # told again when the order comes: the same story
                    self.may(o, ["schedule"], [m["unit"]], actual - 1, order + 5)

    def proximity(self) -> None:
        """A threat within the threat radius of a platoon is contact (a new episode after
        EPISODE_S with none near); within an episode, the nearest threat at 1/CLOSER of
        the distance of the last incident, or the threats near it STRONGER times as
        strong, is a new incident. An alert counts for it from when the change reached
        the MATERIAL step (it is news by then), to a minute after. Positions of hostiles
        are known to sensors within TOLERANCE_M: a threat that only grazes the envelope's
        edge may be told or not; one that comes TOLERANCE_M inside it must be, from when it
        came within TOLERANCE_M of the edge."""
        radius = float(self.voi["threat_radius_m"])
        outer, inner = radius + TOLERANCE_M, radius - TOLERANCE_M
        for o in self.owners:
            plts = sorted(u for u, d in self.units.items() if d["echelon"] == "platoon")
            for u in plts:
                last_near, dist, dist_t0, strength, str_t0 = -1e9, math.inf, None, 0, None
                present: list[float] = []
                pending = None   # an episode whose contact is not yet certain: (began, first within radius)
                told = {"distance": -math.inf, "strength": -math.inf}
                for k, t in enumerate(self.ticks):
                    st = self.subtree(o, t)
                    if u not in st:
                        continue
                    c = self.member_points(u, k).mean(axis=0)
                    near = {h: (float(np.hypot(x - c[0], y - c[1])), s) for h, (x, y, s) in self.hostiles_at(t).items()}
                    near = {h: v for h, v in near.items() if v[0] <= outer}
                    if not near:
                        continue
                    present.append(t)
                    nearest = min(v[0] for v in near.values())
                    total = sum(v[1] for v in near.values() if v[0] <= radius)
                    total_out = sum(v[1] for v in near.values())   # as strong as sensors could make it
                    if t - last_near >= EPISODE_S:   # first contact, or back after a long quiet
                        pending = (t, None)
                    last_near = t
                    if pending is not None:
                        began, within = pending
                        if within is None and nearest <= radius:
                            pending = began, within = (began, t)
                        if nearest <= inner:
                            self.must(o, "contact", PROX, [u, *near], began - 15, t + 15 + self.slack,
                                      f"{sorted(near)} near {u}", at=within, about=[u])
                            dist, dist_t0, strength, str_t0 = nearest, None, total, None
                            told = {"distance": t, "strength": t}
                            pending = None
                        continue
                    if dist_t0 is None and max(nearest - TOLERANCE_M, 0.0) * MATERIAL <= dist:   # sensors err
                        dist_t0 = t
                    if nearest * CLOSER <= dist and t - told["distance"] >= NO_VALUE_S:
                        self.must(o, "distance", PROX, [u], dist_t0 - 15, t + 60, f"threat closer to {u}", at=dist_t0,
                                  about=[u])
                        dist, dist_t0 = nearest, None
                        told["distance"] = t
                    if str_t0 is None and total_out >= MATERIAL * strength:
                        str_t0 = t
                    if total >= STRONGER * strength and t - told["strength"] >= NO_VALUE_S:
                        self.must(o, "strength", PROX, [u], str_t0 - 15, t + 40, f"threat near {u} stronger", at=str_t0,
                                  about=[u])
                        strength, str_t0 = total, None
                        told["strength"] = t
                for a, b in _runs(present):
                    self.may(o, PROX, [u], a - 15, b + 30, about=[u])

    def calls_for_fire(self) -> None:
        for c in self.sim.cffs:
            t = c["t"]
            k = int(round(t / TICK))
            near_leaves, loose = set(), set()
            for leaf in self.leaves:
                pts = self.member_points(leaf, k)
                d = np.hypot(pts[:, 0] - c["x"], pts[:, 1] - c["y"]).min()
                if d <= c["radius_m"]:
                    near_leaves.add(leaf)
                if d <= c["radius_m"] + self.slack * FRIENDLY_MPS:   # as far as a report's age can put it
                    loose.add(leaf)
            for o in self.owners:   # friendly reports are up to `slack` old: near the edge either answer is fair
                mine = loose & self.subtree(o, t)
                if mine:
                    self.may(o, ["call-for-fire"], [self.platoon_of(x, t) for x in mine], t - 1, t + 2)
            if c["kind"] == "cff":
                others = near_leaves - self.subtree(c["requester"], t)
                if others and c["requester"] in self.owners:
                    self.must(c["requester"], "call-for-fire", [], [self.platoon_of(x, t) for x in others], t - 1, t + 2,
                              f"{c['cff']} near friendlies", at=t)
            else:
                for o in self.owners:
                    mine = near_leaves & self.subtree(o, t)
                    if mine:
                        self.must(o, "call-for-fire", [], [self.platoon_of(x, t) for x in mine], t - 1, t + 2,
                                  f"{c['cff']} confirmed near {o}'s units", at=t)
