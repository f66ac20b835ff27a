"""The enemy's tempo on an avenue (a disrupt mission, FM 3-90): from the mission's `by`
time, a hostile track on the avenue (within its width) still advancing along it faster
than the mission's tempo is a disruption that has not worked. Progress is measured along
the avenue as drawn (the way the enemy comes), over at least TREND_S of the track's own
history, so a track milling about or halted on the avenue is not advancing."""
from __future__ import annotations

from collections import deque

import shapely

from ea_agent.core.alert import Candidate, hms

from ..missions import Mission
from .areas import ADVERSARIAL
from .base import Changes, Detector

TREND_S = 60.0    # progress along the avenue is measured over at least this much of a track's history
KEEP_S = 120.0    # history kept per track


class Tempo(Detector):
    TYPES = {"hostile-expected": ADVERSARIAL}

    def reset(self) -> None:
        # mission -> [it, avenue, by, tempo m/s, {track: deque[(t, along)]}, told]
        self.watch: dict[str, list] = {}

    def post(self, m: Mission, avenue: str, by: float, tempo_mps: float) -> None:
        self.watch[m.id] = [m, avenue, by, tempo_mps, {}, False]
        self.dom.areas.reindex()   # its avenue is watched for tracks (what this EA hears of them)

    def end_mission(self, mid: str) -> None:
        if self.watch.pop(mid, None) is not None:
            self.dom.areas.reindex()

    def areas(self) -> set[str]:
        """The avenues watched for the enemy's tempo."""
        return {w[1] for w in self.watch.values()}

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if not self.watch or not ch.tracks or dom.plan is None:
            return
        tracks = dom.pic.tracks
        for mid, w in self.watch.items():
            m, avenue, by, tempo, hist, told = w
            if dom.plan.state.get(mid) not in ("ready", "active") or not dom.in_plan(m):
                continue
            cm = dom.overlay[avenue]
            line, strip = cm.geom, cm.area
            for k in sorted(ch.tracks):
                e = tracks.get(k)
                if e is None or e.strength <= 0 or not strip.contains(shapely.Point(e.x, e.y)):
                    hist.pop(k, None)   # off the avenue: its progress along it starts again
                    continue
                h = hist.setdefault(k, deque())
                if h and h[-1][0] >= t:
                    h.pop()
                h.append((t, float(line.project(shapely.Point(e.x, e.y)))))
                while len(h) > 2 and h[1][0] <= t - TREND_S:
                    h.popleft()
                while h and h[0][0] < t - KEEP_S:
                    h.popleft()
            if told or t < by or dom.plan.state.get(mid) != "active":
                continue
            fast = []
            for k, h in sorted(hist.items()):
                if len(h) < 2 or h[-1][0] - h[0][0] < TREND_S or h[-1][0] != t:
                    continue
                v = (h[-1][1] - h[0][1]) / (h[-1][0] - h[0][0])
                if v > tempo:
                    fast.append((k, v))
            if not fast:
                continue
            w[5] = True
            ids = [k for k, _ in fast]
            top = max(v for _, v in fast)
            strength = sum(tracks[k].strength for k in ids)
            cands.append(Candidate(
                t, "hostile-expected", m.compute_priority("hostile-expected"), (m.unit, *ids),
                f"Tempo not broken on {avenue}: {strength} entities still advancing at up to {top:.1f} m/s "
                f"after {hms(by)} ({dom.name(m.unit)} {m.TYPE}: {tempo:.1f} m/s at most)",
                key=("hostile-expected", mid, "tempo"), measure=top, friendly=False,
                details={"mission": mid, "check": "tempo", "avenue": avenue, "planned_t": by, "tempo_mps": tempo,
                         "speed_mps": round(top, 2), "tracks": ids, "strength": strength, "places": [avenue]}))
