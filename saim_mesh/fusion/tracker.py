"""A Kalman multi-target tracker for forward fusion, in local metres, with motion models
fit for what it tracks (interacting multiple models, IMM).

Why not the scan-window averager (node.py): it confirms a track only with two hits per
sensor in a cluster, so a lone vehicle is never tracked; it averages a window's hits
and stamps them at the window's end, so fast movers lag and split; its gates are fixed
metres. Here each sensor scan is used at its own time; gates come from each track's
covariance (a 300 m/s target and a parked truck get the gates they need); a track is
confirmed when it was updated in M of its last N windows, whatever its size; and a
report describes the track at its last update, with velocity, and is sent only when the
receivers' extrapolation of the last one would be off by more than the track's
dead-reckoning threshold (or the strength or domain changed, or on a heartbeat): dead
reckoning, as DIS does.

Motion models: each track runs three, mixed by an IMM (each is the chance the mover is
doing that now, given the hits): a steady constant velocity with little process noise, a
turning model and a manoeuvring constant velocity with much. What each is depends on
what the track is (`mover`): a ground vehicle drives straight or turns a corner (steady
0.1, manoeuvre 2 m^2/s^3); an aircraft (higher than `air_agl_m`, or faster than any
ground vehicle) also flies coordinated turns and orbits, so its turning model is a
coordinated turn at an estimated turn rate (an extended Kalman filter), and its
manoeuvre model (100 m^2/s^3) catches a hard turn's onset; a tentative track has one
noisy model (it may be anything). A slow aircraft was a ground vehicle to the single
constant-velocity filter this replaces (0.5 m^2/s^3 under 40 m/s): an orbiting UAV got
a new track at every turn.

What is told of a track, and when (dead reckoning): `dead_reckoning.py`.

A track is a group of entities seen together (a hostile unit) or a lone one: the hits
of one scan that fall in a track's gate all update it, their count is its strength,
and their spread its extent (which widens the gate for its members, not for others).
Association per scan, confirmed tracks before tentative ones: one hit per track
(nearest by Mahalanobis distance first), then further hits of the scan join the track
whose gate, widened by its extent, holds them; what is left starts tentative tracks (hits within `birth_m` of each
other: one new track). The tracks of one node are few and so are a scan's hits: the
filter arithmetic is batched over a scan's tracks (motion.py), the association and the
bookkeeping around it are plain Python on lists (a numpy call per track and hit costs
more than the sums it does)."""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from .dead_reckoning import DeadReckoning, Report
from .motion import I3, W0, arc, ct, cv_matrix, imm_mix, kf_update, mixing, mixture, q4


@dataclass
class Track:
    id: str
    x: np.ndarray                    # [x, y, vx, vy, turn rate] at time t
    P: np.ndarray                    # 5 x 5 covariance
    t: float                         # the time x and P describe (the last prediction)
    t_upd: float                     # the last update (what a report describes)
    x_upd: np.ndarray                # the state then
    ext: float = 0.0                 # extent of the group (variance of its members' offsets, m^2)
    counts: deque = field(default_factory=lambda: deque(maxlen=4))   # hits per update (strength)
    seen: deque = field(default_factory=deque)                        # per window: updated or not
    hit_window: bool = False
    confirmed: bool = False
    alt: float | None = None         # metres above ground (mean of its hits' altitudes), if measured
    told: "Report | None" = None     # the last report of it (what receivers extrapolate from)
    trail: deque = field(default_factory=lambda: deque(maxlen=32))   # (t, x, y) after each update
    xs: np.ndarray | None = None     # per motion model (steady, turning, manoeuvring): its state, 3 x 5
    Ps: np.ndarray | None = None     # and covariance, 3 x 5 x 5 (x and P above: their mixture)
    mu: np.ndarray | None = None     # the models' probabilities
    Ps_upd: np.ndarray | None = None  # the models' covariances at the last update (a report's own sigma)


class KalmanTracker:
    def __init__(self, name: str = "K", sigma: dict[str, float] | float = 30.0, q: float = 0.1,
                 q_fast: float = 40.0, fast_mps: float = 40.0, gate: float = 16.0, birth_m: float = 250.0,
                 max_speed_mps: float = 300.0, m: int = 3, n: int = 5, drop_s: float = 35.0,
                 window_s: float = 5.0, air_agl_m: float = 150.0, air_mps: float = 70.0,
                 dr_m: float | None = 40.0, dr_k: float = 3.0, heartbeat_s: float = 60.0,
                 dr_lag_s: float = 0.1, still_m: float = 50.0, still_s: float = 30.0,
                 q_man: float = 2.0, q_air: float = 0.1, q_air_ct: float = 0.2, q_turn: float = 1e-5,
                 q_air_man: float = 100.0, steady_s: float = 60.0, turn_s: float = 300.0, man_s: float = 10.0,
                 max_turn_dps: float = 30.0, dr_m_air: float = 0.0, dr_k_air: float = 4.0,
                 dr_ahead_s: float = 2.5, chord_s: float = 10.0):
        for k, v in (("q", q), ("q_fast", q_fast), ("q_man", q_man), ("q_air", q_air), ("q_air_ct", q_air_ct),
                     ("q_turn", q_turn), ("q_air_man", q_air_man), ("steady_s", steady_s), ("turn_s", turn_s),
                     ("man_s", man_s)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ValueError(f"process noise must be finite and > 0 ({k}={v!r})")
        if not 1 <= m <= n:
            raise ValueError(f"confirmation M-of-N needs 1 <= M <= N, got M={m}, N={n}")
        self.name, self.sigma = name, sigma
        self.q, self.q_fast, self.fast = q, q_fast, fast_mps
        # per kind of mover, three models (steady, turning, manoeuvring): a ground vehicle
        # goes straight or turns a corner; an aircraft also flies coordinated turns and orbits
        self.motion = {"ground": (("cv", q), ("cv", q), ("cv", q_man)),
                       "air": (("cv", q_air), ("ct", q_air_ct), ("cv", q_air_man)),
                       "tentative": (("cv", q_fast),) * 3}
        self._qs = {k: np.array([q for _, q in m]) for k, m in self.motion.items()}
        self._turns = {k: [j for j, (how, _) in enumerate(m) if how == "ct"] for k, m in self.motion.items()}
        # the models' Markov chain: each is left at 1 / its mean sojourn, for either other one alike
        out = np.array([1.0 / steady_s, 1.0 / turn_s, 1.0 / man_s])
        self.rates = (np.ones((3, 3)) - I3) * (out / 2.0)[:, None] - np.diag(out)
        ev, vec = np.linalg.eig(self.rates.T)
        pi = np.real(vec[:, np.argmin(np.abs(ev))])
        self.mu0 = pi / pi.sum()                        # its long-run shares: a new track's
        self.q_turn, self.max_turn = q_turn, math.radians(max_turn_dps)
        self.gate, self.birth_m, self.v0 = gate, birth_m, max_speed_mps / 3.0
        self.m, self.n, self.drop_s, self.window_s = m, n, drop_s, window_s
        self.air_agl_m, self.air_mps = air_agl_m, air_mps
        self.reckon = DeadReckoning(dr_m, dr_k, heartbeat_s, dr_lag_s, dr_m_air, dr_k_air, dr_ahead_s, chord_s,
                                    still_m, still_s, air_agl_m, air_mps)   # what is told, and when
        self._steps: dict[float, tuple] = {}
        self.tracks: list[Track] = []
        self.seq = 0

    def sigma_of(self, sensor: str) -> float:
        s = self.sigma.get(sensor, 30.0) if isinstance(self.sigma, dict) else self.sigma
        if not (math.isfinite(s) and s > 0):
            raise ValueError(f"sensor {sensor!r}: position sigma must be finite and > 0, got {s!r}")
        return float(s)

    # -- one sensor scan ----------------------------------------------------------------
    def scan(self, t: float, sensor: str, z: np.ndarray, alt: np.ndarray | None = None) -> None:
        """The hits `z` (k x 2, metres) one sensor saw at time `t` (not before the last scan);
        `alt`: their heights above ground (k, NaN where unknown), if the sensor gives them."""
        r2 = self.sigma_of(sensor) ** 2
        self._predict(t)
        k = len(z)
        if k == 0:
            return
        zl = np.asarray(z, dtype=float).tolist()
        al = None if alt is None else np.asarray(alt, dtype=float).tolist()
        owner = [-1] * k
        if self.tracks:
            d2, d2g = self._d2(z, r2)
            gate, taken = self.gate, []
            for tier in (True, False):   # confirmed tracks and their members first, then tentative ones
                pairs = sorted((d, i, j) for i, tr in enumerate(self.tracks) if tr.confirmed is tier
                               for j, d in enumerate(d2[i]) if d <= gate and owner[j] < 0)
                now: list[int] = []
                for _, i, j in pairs:   # one hit per track, nearest first
                    if owner[j] < 0 and i not in now:
                        now.append(i)
                        owner[j] = i
                if now:   # the groups' other members join them
                    for j in range(k):
                        if owner[j] < 0:
                            best = min(now, key=lambda i: d2g[i][j])
                            if d2g[best][j] <= gate:
                                owner[j] = best
                taken += now
            if taken:
                taken.sort()
                groups = [[j for j in range(k) if owner[j] == i] for i in taken]
                trs = [self.tracks[i] for i in taken]
                self._update(trs, [[zl[j] for j in g] for g in groups], r2, t)
                if al is not None:
                    for tr, g in zip(trs, groups):
                        self._height(tr, [al[j] for j in g])
        free = [j for j in range(k) if owner[j] < 0]
        if free:
            self._birth([zl[j] for j in free], None if al is None else [al[j] for j in free], r2, t)

    @staticmethod
    def _height(tr: Track, alts: list[float] | None) -> None:
        """The track's height: its hits' mean (NaN: not measured), smoothed."""
        a = [h for h in alts or () if math.isfinite(h)]
        if a:
            m = sum(a) / len(a)
            tr.alt = m if tr.alt is None else 0.5 * tr.alt + 0.5 * m

    # -- motion models ------------------------------------------------------------------
    def mover(self, tr: Track) -> str:
        """What the track moves like: `tentative` until confirmed, then `air` when it flies
        (height above `air_agl_m`) or is faster than `fast_mps` (no ground vehicle is), else
        `ground`. Each has a steady model (constant velocity, little process noise) and a
        manoeuvring one: a coordinated turn for aircraft (they orbit and turn at a rate,
        estimated), a noisier constant velocity on the ground (a vehicle turns a corner)."""
        if not tr.confirmed:
            return "tentative"
        fast = math.hypot(tr.x_upd[2], tr.x_upd[3]) > self.fast
        return "air" if fast or (tr.alt is not None and tr.alt > self.air_agl_m) else "ground"

    def _step(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(the models' mixing matrix, the constant-velocity F, unit process noise) for `dt`:
        the same for every track of a scan, so kept for the last few dts."""
        got = self._steps.get(dt)
        if got is None:
            got = (mixing(self.rates, dt), cv_matrix(dt), q4(1.0, dt))
            if len(self._steps) > 64:
                self._steps.clear()
            self._steps[dt] = got
        return got

    def _predict(self, t: float) -> None:
        """Interacting multiple models (IMM): mix the models' states by the chance each came
        from the other, then predict each by its own motion (the tracks predicted to the
        same time at once)."""
        by: dict[float, list[Track]] = {}
        for tr in self.tracks:
            if t > tr.t:
                by.setdefault(t - tr.t, []).append(tr)
        for dt, trs in by.items():
            Pi, F, Q1 = self._step(dt)
            c, x0, P0 = imm_mix(np.array([tr.mu for tr in trs]), Pi,
                                np.array([tr.xs for tr in trs]), np.array([tr.Ps for tr in trs]))
            kinds = [self.mover(tr) for tr in trs]
            qs = np.array([self._qs[k] for k in kinds])
            nx = x0 @ F.T                                           # every model as constant velocity first
            nP = F @ P0 @ F.T + qs[:, :, None, None] * Q1
            nP[:, :, 4, 4] += W0
            turns = [(i, j) for i, k in enumerate(kinds) for j in self._turns[k]]
            if turns:                                               # then the turning ones as they turn
                ti, tj = np.array(turns).T
                nx[ti, tj], nP[ti, tj] = ct(x0[ti, tj], P0[ti, tj], qs[ti, tj], self.q_turn, self.max_turn, dt)
            X, P = mixture(c, nx, nP)
            for i, tr in enumerate(trs):
                tr.xs, tr.Ps, tr.mu, tr.x, tr.P, tr.t = nx[i], nP[i], c[i], X[i], P[i], t

    def _d2(self, z: np.ndarray, r2: float) -> tuple[list[list[float]], list[list[float]]]:
        """Squared Mahalanobis distance of every hit to every track's predicted position,
        the least over its motion models (a hit a manoeuvre explains is in the gate): plain,
        and with the gate widened by the track's extent (for a group's other members)."""
        xs = np.array([tr.xs for tr in self.tracks])[:, :, :2]           # T x 3 x 2
        Ps = np.array([tr.Ps for tr in self.tracks])
        s00, s01, s11 = Ps[:, :, 0, 0] + r2, Ps[:, :, 0, 1], Ps[:, :, 1, 1] + r2
        v = np.asarray(z, dtype=float)[None, None] - xs[:, :, None, :]   # T x 3 x hits x 2
        vx2, vxy, vy2 = v[..., 0] ** 2, 2.0 * v[..., 0] * v[..., 1], v[..., 1] ** 2

        def d2(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> list[list[float]]:
            det = (a * c - b * b)[..., None]
            return ((c[..., None] * vx2 - b[..., None] * vxy + a[..., None] * vy2) / det).min(axis=1).tolist()
        plain = d2(s00, s01, s11)
        ext = np.array([tr.ext for tr in self.tracks])
        if not ext.any():
            return plain, plain
        e = ext[:, None]
        return plain, d2(s00 + e, s01, s11 + e)

    def _update(self, trs: list[Track], zs: list[list[list[float]]], r2: float, t: float) -> None:
        """Each track by the hits of this scan it took (`zs`, one list per track): their mean
        is one measurement of it, its noise the sensor's and the group's extent over their count."""
        zc, R = [], []
        for tr, g in zip(trs, zs):
            n = len(g)
            if n == 1:
                cx, cy = g[0]
            else:   # the members' spread, beyond the sensor's noise
                cx, cy = sum(p[0] for p in g) / n, sum(p[1] for p in g) / n
                spread = sum((x - cx) ** 2 + (y - cy) ** 2 for x, y in g) / n / 2.0
                tr.ext = 0.7 * tr.ext + 0.3 * max(spread - r2, 0.0)
            zc.append((cx, cy))
            R.append((r2 + tr.ext) / n)
        xs, Ps, ll = kf_update(np.array([tr.xs for tr in trs]), np.array([tr.Ps for tr in trs]),
                               np.array(zc), np.array(R))
        mu = np.array([tr.mu for tr in trs]) * np.exp(ll - ll.max(axis=1, keepdims=True))
        mu = np.clip(mu / mu.sum(axis=1, keepdims=True), 1e-6, 1.0)
        mu /= mu.sum(axis=1, keepdims=True)
        X, P = mixture(mu, xs, Ps)
        for i, (tr, g) in enumerate(zip(trs, zs)):
            tr.xs, tr.Ps, tr.mu, tr.x, tr.P = xs[i], Ps[i], mu[i], X[i], P[i]
            tr.Ps_upd, tr.x_upd = tr.Ps, tr.x     # fresh arrays, never changed in place
            tr.t = tr.t_upd = t
            tr.counts.append(len(g))
            tr.trail.append((t, float(X[i, 0]), float(X[i, 1])))
            tr.hit_window = True

    def _birth(self, z: list[list[float]], alt: list[float] | None, r2: float, t: float) -> None:
        """New tentative tracks from the hits no track took: one per cluster of hits within
        `birth_m` of each other."""
        n = len(z)
        label = [-1] * n
        for s in range(n):                    # connected components within birth_m
            if label[s] >= 0:
                continue
            label[s], stack = s, [s]
            while stack:
                xi, yi = z[stack.pop()]
                for j in range(n):
                    if label[j] < 0 and math.hypot(z[j][0] - xi, z[j][1] - yi) <= self.birth_m:
                        label[j] = s
                        stack.append(j)
        for lab in sorted(set(label)):
            mine = [j for j in range(n) if label[j] == lab]
            m = len(mine)
            cx, cy = sum(z[j][0] for j in mine) / m, sum(z[j][1] for j in mine) / m
            spread = sum((z[j][0] - cx) ** 2 + (z[j][1] - cy) ** 2 for j in mine) / m / 2.0
            ext = max(spread - r2, 0.0) if m > 1 else 0.0
            pv = r2 + ext
            self.seq += 1
            x = np.array([cx, cy, 0.0, 0.0, 0.0])
            P = np.diag([pv, pv, self.v0 ** 2, self.v0 ** 2, W0])
            tr = Track(f"{self.name}-{self.seq}", x, P, t, t, x.copy(), ext)
            tr.xs, tr.Ps = np.stack([x, x, x]), np.stack([P, P, P])
            tr.mu, tr.Ps_upd = self.mu0.copy(), tr.Ps.copy()
            tr.counts.append(m)
            tr.hit_window = True
            if alt is not None:
                self._height(tr, [alt[j] for j in mine])
            self.tracks.append(tr)

    # -- window close: confirmation, deletion, reports -----------------------------------
    def close_window(self, t: float) -> list[Report]:
        """Confirm (M of N windows), drop, and report each confirmed track updated in this
        window (strength 0 for a confirmed track dropped: the mesh forgets it)."""
        out: list[Report] = []
        keep = []
        for tr in self.tracks:
            tr.seen.append(tr.hit_window)
            if len(tr.seen) > self.n:
                tr.seen.popleft()
            hit, tr.hit_window = tr.seen[-1], False
            if not tr.confirmed and sum(tr.seen) >= self.m:
                tr.confirmed = True
            stale = t - tr.t_upd > self.drop_s
            hopeless = not tr.confirmed and len(tr.seen) >= self.n and sum(tr.seen) < self.m
            if stale or hopeless:
                if tr.confirmed:
                    out.append(self.reckon.report(tr, 0))
                continue
            keep.append(tr)
            if tr.confirmed and hit:
                r = self.reckon.report(tr)
                if self.reckon.news(tr, r, self.mover(tr) == "air", lambda h, tr=tr: self._ahead(tr, h)):
                    tr.told = r
                    out.append(r)
        self.tracks = keep
        return out

    def _ahead(self, tr: Track, t: float) -> tuple[float, float]:
        """The track's expected position at `t` (its models' predictions, by their weights)."""
        dt = t - tr.t
        if dt <= 0:
            return float(tr.x[0]), float(tr.x[1])
        px = py = 0.0
        for (how, _), m, (x, y, vx, vy, w) in zip(self.motion[self.mover(tr)], tr.mu.tolist(), tr.xs.tolist()):
            if how == "ct":
                x, y = arc(x, y, vx, vy, min(max(w, -self.max_turn), self.max_turn), dt)
            else:
                x, y = x + vx * dt, y + vy * dt
            px, py = px + m * x, py + m * y
        return px, py

    def dr_threshold(self, tr: Track) -> float:
        """The dead-reckoning threshold of this track (`DeadReckoning.threshold`)."""
        return self.reckon.threshold(tr, self.mover(tr) == "air")

    def domain(self, tr: Track) -> str:
        return self.reckon.domain(tr)
