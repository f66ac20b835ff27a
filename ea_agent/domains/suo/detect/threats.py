"""Threat envelopes (paper 6.7.1): hostile tracks close enough to threaten each
platoon-level unit, told as contact, closer, stronger, and merged per parent as
proximity."""
from __future__ import annotations

import math
from math import hypot
from operator import itemgetter

import numpy as np

from ea_agent.core.alert import Candidate
from ea_agent.core.geo import bearing_name

from ..render import km
from .assemble import hold_first
from .base import Changes, Detector

ADVERSARIAL = "adversarial-activity"


class ThreatEnvelopes(Detector):
    """A unit is re-evaluated only when it moved or a track in or near its envelope
    changed, so what happens far away (which a mesh peer may never receive)
    cannot change its alerts."""
    TYPES = {"contact": ADVERSARIAL, "distance": ADVERSARIAL, "strength": ADVERSARIAL,
             "proximity": ADVERSARIAL}   # proximity: the merged alert (render.merge)

    def __init__(self, dom) -> None:
        super().__init__(dom)
        # unit -> (tracks in its envelope, nearest distance, strength) when last evaluated;
        # kept across plan changes, the tracks are still there
        self.env_prev: dict[str, tuple[frozenset, float, int]] = {}

    def org_changed(self) -> None:
        self.env_prev = {u: v for u, v in self.env_prev.items() if u in self.dom.own_units}
        self._told: dict[str, tuple] = {}   # unit -> (envelope state, what is told of it)
        self._exact: dict[tuple, float] = {}   # (unit position, reckoned position, track position) -> distance

    def _render(self, u: str, m, fs: int, ids: frozenset, nearest: float, strength: int, tr, upx, danger: float):
        """The parts of an envelope's candidates that depend only on its state."""
        dom = self.dom
        where = f"{km(nearest)} {bearing_name(tr.x - upx[0], tr.y - upx[1])} of {dom.name(u)}"
        tracks = sorted(ids)
        base = dict(unit=u, nearest_track=tr.id, distance_m=round(nearest, 1), strength=strength,
                    friendly_strength=fs, tracks=tracks, mission=m.id if m is not dom.base else None)
        rec = ((("threat", u, "distance"), 1000.0 / max(nearest, 1.0)), (("threat", u, "strength"), float(strength)))
        return (where, base, (u, *tracks), ("prox", dom.taskorg.parent.get(u) or u), rec,
                m.red_alert_priority("distance", fs, strength, nearest, danger),
                m.red_alert_priority("strength", fs, strength, nearest, danger))

    def _dmax(self, p: tuple, q: tuple, xy: tuple) -> float:
        """How far a track is from the farther of the unit's two positions, exactly as
        numpy computes it (math.hypot may differ in the last bit); remembered, as a
        contact that stands still is asked again at every periodic re-evaluation."""
        key = (p, q, xy)
        d = self._exact.get(key)
        if d is None:
            if len(self._exact) > 4096:
                self._exact.clear()
            x, y = xy
            d = self._exact[key] = max(float(np.hypot(p[0] - x, p[1] - y)), float(np.hypot(q[0] - x, q[1] - y)))
        return d

    def _close(self, p: tuple, q: tuple, tpos: list, ks, radius: float) -> list[tuple[int, float]]:
        """(index, distance) of the tracks among `ks` within `radius` of both positions.
        math.hypot (cheap) rules out the tracks clearly beyond reach; only those within
        reach of its last-bit error are measured exactly."""
        reach = radius * (1.0 + 1e-9) + 1e-9
        px, py = p
        qx, qy = q
        out = []
        for k in ks:
            x, y = xy = tpos[k]
            if hypot(px - x, py - y) <= reach and hypot(qx - x, qy - y) <= reach:
                d = self._dmax(p, q, xy)
                if d <= radius:
                    out.append((k, d))
        return out

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        rescan = ch.rescan   # periodic: keeps a continuing contact's story alive
        if not (rescan or ch.tracks or ch.units.intersection(dom.env_units)):
            return
        radius = float(dom.voi_cfg["threat_radius_m"])
        danger = float(dom.voi_cfg["danger_close_m"])
        pic = dom.pic
        tracks = pic.tracks
        tids = sorted(tracks)
        tpos = [(tracks[k].x, tracks[k].y) for k in tids]
        every = range(len(tids))
        moved = [k for k, tid in enumerate(tids) if tid in ch.tracks]
        # a threat is in a unit's envelope when it is within reach of where the unit was
        # last reported and of where it is dead-reckoned to be now: a report a minute old
        # misplaces a moving unit, and reckoning overshoots one that has just stopped
        unit_pos, unit_now = dom.unit_pos, dom.unit_now
        empty = frozenset()
        for u in dom.env_units:
            p = unit_pos.get(u)
            if not p:
                continue
            q = unit_now.get(u) or p
            prev0 = self.env_prev.get(u, (empty,))[0]
            if not (rescan and prev0) and u not in ch.units and not prev0 & ch.tracks \
                    and not (moved and self._close(p, q, tpos, moved, radius)):
                continue
            near = self._close(p, q, tpos, every, radius) if tids else []
            if not near:
                if prev0:
                    self.env_prev[u] = (empty, math.inf, 0)
                dom.assembly.drop_key(("threat", u, "contact"))   # gone before its group assembled
                continue
            ids = frozenset(tids[k] for k, _ in near)
            prev = self.env_prev.get(u, (empty, math.inf, 0))
            k_near, nearest = min(near, key=itemgetter(1))
            strength = int(sum(tracks[tids[k]].strength for k, _ in near))
            self.env_prev[u] = (ids, nearest, strength)
            m = dom.current_mission(u)
            fs = len(pic.members[u])
            tr = tracks[tids[k_near]]
            upx = p
            # what is told of this envelope: rebuilt only when something in it changed (a
            # periodic re-evaluation of a contact that stands still finds the same)
            state = (ids, nearest, strength, m, fs, tr.id, tr.x, tr.y, upx, danger)
            told = self._told.get(u)
            if told is None or told[0] != state:
                told = self._told[u] = (state, *self._render(u, m, fs, ids, nearest, strength, tr, upx, danger))
            _, where, base, subj, group, rec, p_distance, p_strength = told
            new = ids - prev[0]
            voa = dom.ea.voa
            ckey = ("threat", u, "contact")
            # A contact is told when a threat enters an empty envelope; while the envelope
            # stays occupied the story goes on and the user is not told it again (touch);
            # after the expiry with none near, a threat back is a new contact.
            # A contact waits for the rest of its group (assemble.py): while it is held, every
            # re-evaluation offers it again, counting what is near now.
            remembered = voa.enabled and voa.last(ckey, t) is not None
            if remembered:
                voa.touch(ckey, t)
            elif new or not voa.enabled or dom.assembly.holds(ckey):   # VOA off (naive): every re-evaluation
                p = m.red_alert_priority("contact", fs, strength, nearest, danger)
                c = Candidate(t, "contact", p, subj, f"Contact: {strength} hostile entities {where}",
                              key=ckey, friendly=False, merge_group=group, also=rec, count=strength,
                              details={**base, "new_tracks": sorted(new)})
                if not hold_first(dom, c, new or ids, bool(new)):
                    cands.append(c)
            if remembered or not voa.enabled:
                # Propose on every re-evaluation; VOA compares with what the user was last told.
                if not new:
                    cands.append(Candidate(t, "distance", p_distance, subj, f"Closest threat is now closer: {where}",
                                           key=("threat", u, "distance"), measure=1000.0 / max(nearest, 1.0),
                                           friendly=False, merge_group=group, details=dict(base)))
                if p_strength is not None:
                    cands.append(Candidate(t, "strength", p_strength, subj,
                                           f"Threat near {dom.name(u)} stronger: {strength} hostile entities, "
                                           f"nearest {where}",
                                           key=("threat", u, "strength"), measure=float(strength), friendly=False,
                                           merge_group=group, count=strength, details=dict(base)))
