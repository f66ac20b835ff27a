"""Escape: a hostile must not leave an area the mission holds it in (fix, isolate,
destroy: the objective; contain: the engagement area), a fix only until its time if it
has one. A track seen inside while the mission runs that is later beyond the area's edge band (not only flickering at the
edge with its reports' noise) has escaped; one that is lost is not told as escaped.
One story per area: two missions holding the same objective tell one escape."""
from __future__ import annotations

from collections import defaultdict

from ea_agent.core.alert import Candidate

from ..missions import Mission
from .areas import ADVERSARIAL
from .base import Changes, Detector


class Escapes(Detector):
    TYPES = {"escape": ADVERSARIAL}

    def reset(self) -> None:
        self.watch: dict[str, list[Mission]] = defaultdict(list)   # area -> missions holding hostiles in it
        self.held: dict[str, set[str]] = {}                          # mission -> tracks seen inside
        self.until: dict[str, float] = {}                            # mission -> held there until then

    def post(self, m: Mission, area: str, until: float | None = None) -> None:
        self.watch[area].append(m)
        if until is not None:
            self.until[m.id] = until
        self.dom.areas.reindex()

    def areas(self) -> set[str]:
        """Areas the Areas component must index for us."""
        return {a for a, ms in self.watch.items() if ms}

    def end_mission(self, mid: str) -> None:
        for a in list(self.watch):
            self.watch[a] = [m for m in self.watch[a] if m.id != mid]
        self.held.pop(mid, None)
        self.until.pop(mid, None)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if not ch.tracks or dom.plan is None or not self.watch:
            return
        areas, tracks = dom.areas, dom.pic.tracks
        for area, ms in self.watch.items():
            inside = areas.tracks.get(area, set())
            near = {k for a, k in areas._present if a == area}
            gone: set[str] = set()
            holders: list[Mission] = []
            for m in ms:
                if dom.plan.state.get(m.id) != "active" or not dom.in_plan(m) or t > self.until.get(m.id, t):
                    continue
                held = self.held.setdefault(m.id, set())
                held |= inside
                held.difference_update([k for k in held if k not in tracks])   # lost, not escaped
                out = {k for k in held if k not in near}
                if out:
                    held -= out
                    gone |= out
                    holders.append(m)
            if not gone:
                continue
            ids = sorted(gone)
            strength = sum(tracks[k].strength for k in ids)
            m = holders[0]
            who = ", ".join(f"{dom.name(x.unit)} {x.TYPE}" for x in holders)
            cands.append(Candidate(
                t, "escape", m.compute_priority("escape"), tuple(ids),
                f"Hostiles escaping {area} held by {who}: {strength} entities in "
                f"{len(ids)} track{'s' if len(ids) > 1 else ''}",
                key=("escape", area), measure=float(strength), friendly=False, news=True,
                details={"mission": m.id, "missions": [x.id for x in holders], "place": area, "places": [area],
                         "strength": strength, "tracks": ids}))
