"""A fusion node on the Kalman tracker (tracker.py): the same interface as `FusionNode`
(hits in, `SensorTrack` reports out at each window's close), so the runner and the
fusion peer can use either. Hits are projected once per window (one pyproj call) and
fed to the tracker scan by scan, each at its own time. A report is issued at the
window's close (`t`: so an in-process run and a mesh peer apply it in the same epoch)
and carries the time its position describes (`at`: its last hit), heading and speed."""
from __future__ import annotations

import math

import numpy as np

from ea_agent.core.geo import Projection
from saim_mesh.protocol.messages import SensorHit, SensorTrack

from .node import Windowed
from .tracker import KalmanTracker


class KalmanNode(Windowed):
    def __init__(self, node_id: str, proj: Projection, sigma: dict[str, float] | float = 30.0,
                 window_s: float = 5.0, **tracker):
        super().__init__(node_id, proj, window_s)
        self.tracker = KalmanTracker(node_id, sigma, window_s=window_s, **tracker)

    @property
    def seq(self) -> int:
        """The highest track number given so far (the fusion peer's tick carries it)."""
        return self.tracker.seq

    def _close(self, t: float) -> list[SensorTrack]:
        self.stats["windows"] += 1
        hits, self.pending = self.pending, []
        if hits:
            x, y = self.proj.to_xy(np.array([h.lon for h in hits]), np.array([h.lat for h in hits]))
            xy = np.column_stack([np.atleast_1d(x), np.atleast_1d(y)])
            alt = np.array([np.nan if h.alt is None else h.alt for h in hits])
            start = 0
            for i in range(1, len(hits) + 1):   # one scan: one sensor's hits at one time
                if i == len(hits) or (hits[i].t, hits[i].sensor) != (hits[start].t, hits[start].sensor):
                    a = alt[start:i]
                    self.tracker.scan(hits[start].t, hits[start].sensor, xy[start:i],
                                      a if np.isfinite(a).any() else None)
                    start = i
        out = [self._track(r, t) for r in self.tracker.close_window(t)]
        out.sort(key=lambda r: r.track)
        self.stats["tracks_out"] += len(out)
        return out

    def _track(self, r, t: float) -> SensorTrack:
        lon, lat = self.proj.to_lonlat(r.x, r.y)
        heading = (math.degrees(math.atan2(r.vx, r.vy)) + 360.0) % 360.0
        return SensorTrack(t, r.track, round(float(lon), 7), round(float(lat), 7), r.strength,
                           round(heading, 1) % 360.0, round(math.hypot(r.vx, r.vy), 2), self.id, r.alt, r.domain,
                           round(r.t, 3))
