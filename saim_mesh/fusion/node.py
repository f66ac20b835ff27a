"""A fusion node: associates one sensor group's hits into tracks and publishes tracks,
not hits.

Each scan window (scenario time) it projects the window's hits in one pyproj call,
clusters them (hits within `cluster_m` of each other are one group of entities),
gates the clusters against the tracks' predicted positions (alpha-beta filter) and
assigns them greedily by distance (vectorised with numpy). A track is confirmed
after `confirm_n` updates averaging two or more hits (a lone false alarm seldom
repeats in the gate, two at once almost never), and dropped after `drop_s` without one. Strength is the
most hits one sensor saw in the cluster, the largest over the last few windows
(a sensor sees each entity at most once a scan, and misses some).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ea_agent.core.geo import Projection
from saim_mesh.protocol.messages import SensorHit, SensorTrack


@dataclass
class _Track:
    id: str
    x: float
    y: float
    vx: float = 0.0
    vy: float = 0.0
    t: float = 0.0
    hits: int = 1
    counts: deque = field(default_factory=lambda: deque(maxlen=4))
    confirmed: bool = False


class Windowed:
    """Hits in, time-ordered; every `window_s` of scenario time the window's hits go to
    `_close(t)`, which returns the window's track reports. Both fusion nodes are this."""

    def __init__(self, node_id: str, proj: Projection, window_s: float):
        self.id, self.proj, self.window_s = node_id, proj, window_s
        self.pending: list[SensorHit] = []
        self.window_end = window_s
        self.stats = {"hits_in": 0, "tracks_out": 0, "windows": 0}

    def add(self, hit: SensorHit) -> list[SensorTrack]:
        """Take one hit (time-ordered); returns the track reports of any window it closed."""
        out = self.flush(hit.t)   # a hit at a window's end belongs to the next one
        self.pending.append(hit)
        self.stats["hits_in"] += 1
        return out

    def flush(self, t: float) -> list[SensorTrack]:
        """Close every window that ends at or before `t`."""
        out: list[SensorTrack] = []
        while self.window_end <= t:
            out += self._close(self.window_end)
            self.window_end += self.window_s
        return out

    def _close(self, t: float) -> list[SensorTrack]:
        raise NotImplementedError


class FusionNode(Windowed):
    def __init__(self, node_id: str, proj: Projection, window_s: float = 5.0, cluster_m: float = 250.0,
                 gate_m: float = 400.0, confirm_n: int = 3, drop_s: float = 35.0, alpha: float = 0.6,
                 beta: float = 0.2):
        super().__init__(node_id, proj, window_s)
        self.cluster_m, self.gate_m = cluster_m, gate_m
        self.confirm_n, self.drop_s, self.alpha, self.beta = confirm_n, drop_s, alpha, beta
        self.tracks: list[_Track] = []
        self.seq = 0

    # -- one scan window ----------------------------------------------------------------------
    def _clusters(self, xy: np.ndarray, sensors: list[str]) -> list[tuple[float, float, int]]:
        n = len(xy)
        d = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
        adj = d <= self.cluster_m
        label = -np.ones(n, dtype=int)
        for s in range(n):                       # connected components (n is small per window)
            if label[s] >= 0:
                continue
            label[s] = s
            stack = [s]
            while stack:
                i = stack.pop()
                for j in np.nonzero(adj[i] & (label < 0))[0]:
                    label[j] = s
                    stack.append(int(j))
        out = []
        for lab in np.unique(label):
            m = label == lab
            per_sensor: dict[str, int] = {}
            for k in np.nonzero(m)[0]:
                per_sensor[sensors[k]] = per_sensor.get(sensors[k], 0) + 1
            c = xy[m].mean(axis=0)
            out.append((float(c[0]), float(c[1]), max(per_sensor.values())))
        return out

    def _close(self, t: float) -> list[SensorTrack]:
        self.stats["windows"] += 1
        hits, self.pending = self.pending, []
        meas: list[tuple[float, float, int]] = []
        if hits:
            x, y = self.proj.to_xy(np.array([h.lon for h in hits]), np.array([h.lat for h in hits]))
            meas = self._clusters(np.column_stack([np.atleast_1d(x), np.atleast_1d(y)]), [h.sensor for h in hits])
        # predict, gate and assign (greedy by distance)
        used_t, used_m = set(), set()
        if self.tracks and meas:
            px = np.array([tr.x + tr.vx * (t - tr.t) for tr in self.tracks])
            py = np.array([tr.y + tr.vy * (t - tr.t) for tr in self.tracks])
            mx, my = np.array([m[0] for m in meas]), np.array([m[1] for m in meas])
            d = np.hypot(px[:, None] - mx[None, :], py[:, None] - my[None, :])
            for flat in np.argsort(d, axis=None, kind="stable"):
                i, j = divmod(int(flat), len(meas))
                if d[i, j] > self.gate_m:
                    break
                if i in used_t or j in used_m:
                    continue
                used_t.add(i)
                used_m.add(j)
                self._update(self.tracks[i], meas[j], t, px[i], py[i])
        for j, m in enumerate(meas):
            if j not in used_m:
                self.seq += 1
                tr = _Track(f"{self.id}-{self.seq}", m[0], m[1], t=t)
                tr.counts.append(m[2])
                self.tracks.append(tr)
        out: list[SensorTrack] = []
        keep = []
        for tr in self.tracks:
            if t - tr.t > self.drop_s:
                if tr.confirmed:   # tell the mesh the track is gone
                    out.append(self._report(tr, t, strength=0))
                continue
            keep.append(tr)
            if tr.confirmed and tr.t == t:
                out.append(self._report(tr, t))
        self.tracks = keep
        self.stats["tracks_out"] += len(out)
        return out

    def _update(self, tr: _Track, m, t: float, px: float, py: float) -> None:
        dt = max(t - tr.t, 1e-6)
        rx, ry = m[0] - px, m[1] - py
        tr.x, tr.y = px + self.alpha * rx, py + self.alpha * ry
        tr.vx += self.beta * rx / dt
        tr.vy += self.beta * ry / dt
        tr.t = t
        tr.hits += 1
        tr.counts.append(m[2])
        if tr.hits >= self.confirm_n and sum(tr.counts) >= 2 * min(len(tr.counts), self.confirm_n):
            tr.confirmed = True   # seen in enough windows, with more than lone (false-alarm-like) hits

    def _report(self, tr: _Track, t: float, strength: int | None = None) -> SensorTrack:
        lon, lat = self.proj.to_lonlat(tr.x, tr.y)
        speed = math.hypot(tr.vx, tr.vy)
        heading = (math.degrees(math.atan2(tr.vx, tr.vy)) + 360.0) % 360.0
        return SensorTrack(t, tr.id, round(float(lon), 7), round(float(lat), 7),
                           max(tr.counts) if strength is None else strength, round(heading, 1),
                           round(speed, 2), self.id)
