"""What a tracker tells of its tracks, and when: dead reckoning, as DIS does. A report
describes a track at its last update, with velocity; it is sent only when the receivers'
extrapolation of the last one would be off by more than the track's threshold (now, or a
moment ahead along the track's own motion models: a turn is told as it begins), or its
strength or domain changed, or on a heartbeat.

The threshold (`threshold`) scales with the track's class and speed: k times its steady
model's position sigma plus `dr_lag_s` of its motion, and for ground tracks at least
`dr_m` (k = 3 on the ground, 4 in the air), so what receivers hold between reports stays
within about the tracker's own error at far fewer reports than hits. An aircraft's report
in a turn carries the chord of its next `chord_s` of arc as velocity (receivers
extrapolate in straight lines); a halted group is told still (no drift by its velocity
noise)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable


@dataclass
class Report:
    """What the tracker says of one track: its state at its last update."""
    t: float
    track: str
    x: float
    y: float
    vx: float
    vy: float
    strength: int
    alt: float | None = None
    domain: str = "ground"


@dataclass
class DeadReckoning:
    """The tracker's telling rule, its parameters named as the tracker's (`KalmanTracker`)."""
    dr_m: float | None = 40.0
    dr_k: float = 3.0
    heartbeat_s: float = 60.0
    dr_lag_s: float = 0.1
    dr_m_air: float = 0.0
    dr_k_air: float = 4.0
    dr_ahead_s: float = 2.5
    chord_s: float = 10.0
    still_m: float = 50.0
    still_s: float = 30.0
    air_agl_m: float = 150.0
    air_mps: float = 70.0

    def news(self, tr, r: Report, air: bool, ahead: Callable[[float], tuple[float, float]]) -> bool:
        """Whether receivers need this report: the first one, a new strength or domain, the
        heartbeat, or their extrapolation of the last one (position + velocity x time) off
        by more than `threshold` now or `dr_ahead_s` ahead (`ahead(t)`: where the track's
        own models put it then; `dr_m` None: every update is sent)."""
        last = tr.told
        if self.dr_m is None or last is None or (r.strength, r.domain) != (last.strength, last.domain):
            return True
        if r.t - last.t >= self.heartbeat_s:
            return True
        dt = r.t - last.t
        lim = self.threshold(tr, air)
        if math.hypot(last.x + last.vx * dt - r.x, last.y + last.vy * dt - r.y) > lim:
            return True
        if self.dr_ahead_s <= 0:
            return False
        h = r.t + self.dr_ahead_s
        px, py = ahead(h)
        return math.hypot(last.x + last.vx * (h - last.t) - px, last.y + last.vy * (h - last.t) - py) > lim

    def threshold(self, tr, air: bool) -> float:
        """How far the receivers' extrapolation may be off before a report is news: k x the
        track's own position sigma (its steady model's: its noise is no news) plus
        `dr_lag_s` of its motion (nor is an error of where it is a moment later), k by its
        class (`dr_k` ground, `dr_k_air` air), at least `dr_m` for ground tracks (`dr_m_air`
        in the air). A fast jet's threshold is wider than a slow aircraft's, an aircraft's
        follows its own error where a ground unit's has a floor in metres."""
        P = tr.Ps_upd[0]
        sig = math.sqrt(max(float(P[0, 0]), float(P[1, 1])))
        speed = math.hypot(tr.x_upd[2], tr.x_upd[3])
        floor, k = (self.dr_m_air, self.dr_k_air) if air else (self.dr_m, self.dr_k)
        return max(floor, k * sig + self.dr_lag_s * speed)

    def domain(self, tr) -> str:
        """Air when it flies (height above `air_agl_m`) or moves faster than any ground
        vehicle (`air_mps`); else ground."""
        fast = math.hypot(tr.x_upd[2], tr.x_upd[3]) > self.air_mps
        return "air" if fast or (tr.alt is not None and tr.alt > self.air_agl_m) else "ground"

    def halted(self, tr) -> bool:
        """Whether the track stands still: it moved less than `still_m` over the last
        `still_s` (a net displacement, which the velocity's scan-to-scan noise does not
        fake); a track younger than that: its velocity within twice its own sigma."""
        old = [(t, x, y) for t, x, y in tr.trail if tr.t_upd - t >= self.still_s]
        if old:
            _, x0, y0 = old[-1]
            return math.hypot(tr.x_upd[0] - x0, tr.x_upd[1] - y0) < self.still_m
        return math.hypot(tr.x_upd[2], tr.x_upd[3]) < 2.0 * math.sqrt(max(float(tr.P[2, 2]), float(tr.P[3, 3])))

    def report(self, tr, strength: int | None = None) -> Report:
        """The track at its last update, as receivers should extrapolate it."""
        x = tr.x_upd
        vx, vy = float(x[2]), float(x[3])
        if self.halted(tr):
            vx = vy = 0.0   # receivers must not drift a halted group by its velocity noise
        elif self.chord_s > 0 and abs(x[4]) * self.chord_s > 1e-3:
            th = float(x[4]) * self.chord_s / 2.0   # the chord of the next chord_s of the arc
            f = math.sin(th) / th
            c, s_ = math.cos(th), math.sin(th)
            vx, vy = f * (c * vx - s_ * vy), f * (s_ * vx + c * vy)
        return Report(tr.t_upd, tr.id, float(x[0]), float(x[1]), vx, vy,
                      max(tr.counts) if strength is None else strength,
                      None if tr.alt is None else round(tr.alt, 1), self.domain(tr))
