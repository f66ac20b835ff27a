"""The console's model of the battle: what the commander's page shows, fed from the
mesh (feed.py) or from in-process EAs, read by the web server (server.py).

Pure Python (no Zenoh, no asyncio): every input is a decoded message or alert, so it
is unit-testable. Thread-safe: the feed thread writes, the server's loop reads. High-rate
inputs (positions, tracks, the clock) only mark the model dirty; `drain()` (called at
most every 100 ms by the server) turns what changed into events, so 2,500 location
reports a second cost a dict update each, not a browser update each.
"""
from __future__ import annotations

import threading
from collections import deque
from typing import Any

from ea_agent import domains

from .missions import Missions
from .overlay import overlay_geojson

MAX_ALERTS = 5000          # alerts kept for the snapshot (ids are kept for all)
MAX_OUTBOX = 10_000        # alerts/results waiting for the next drain (no server running)
TRACK_TTL_S = 600.0        # a track not reported for this long leaves the picture


class State:
    def __init__(self, sc, unit: str | None = None, actors: list[str] | None = None,
                 eligible: list[str] | None = None):
        """`actors`: the units this console acts for, fixed (in process: every EA run);
        else `eligible` (the units with an EA peer; default all) under `unit` in the task
        organization as it is now, following reorganizations as their EAs do."""
        self.sc = sc
        self.taskorg = sc.taskorg.copy()
        self.unit = unit or self.taskorg.root
        if self.unit not in self.taskorg.units:
            raise KeyError(f"unknown unit {self.unit!r}: not in the task organization of {sc.name}")
        self._fixed = sorted(actors) if actors is not None else None
        self._eligible = set(eligible) if eligible is not None else set(self.taskorg.units)
        planned = getattr(domains.of(sc), "org_changes", None)
        self._planned = deque(planned(sc) if planned else [])   # (t, unit, new parent), in time order
        self.silences: dict[str, dict] = {}   # silences this console made that the EA took, by id
        self.lock = threading.Lock()
        self.t = 0.0
        self.ended = False
        self.alerts: deque[dict] = deque(maxlen=MAX_ALERTS)
        self.alert_owner: dict[str, str] = {}       # alert id -> owner (every alert seen)
        self.counts: dict[str, dict[str, int]] = {}
        self.entity_pos: dict[str, tuple[float, float]] = {}
        self.tracks: dict[str, tuple[float, float, int, float]] = {}   # id -> lon, lat, strength, t
        self.cffs: set[str] = set()
        self.missions = Missions(sc, self.taskorg)
        self.overlay = overlay_geojson(sc)
        self._outbox: deque[tuple[str, Any]] = deque(maxlen=MAX_OUTBOX)
        self._dirty: set[str] = set()
        self._sent_missions: dict | None = None
        self._ticks: deque[tuple[float, float]] = deque(maxlen=MAX_OUTBOX)   # (t, wall) since the last drain

    # -- inputs (any thread) ----------------------------------------------------------
    def clock(self, t: float, end: bool = False, w: float | None = None) -> None:
        """The mesh clock reached `t`; `w`: the wall time the replay published that tick
        (passed on to the page, which measures raise-to-render latency against it)."""
        with self.lock:
            if t > self.t:
                self.t = t
                self._dirty.add("clock")
                if w is not None:
                    self._ticks.append((t, w))
                while self._planned and self._planned[0][0] <= t:   # as the EAs execute them
                    _, u, parent = self._planned.popleft()
                    self._resubordinate(u, parent)
            self.ended = self.ended or end

    def alert(self, a) -> None:
        """One alert (an `Alert`): pushed individually, counted per owner and type."""
        d = a.to_json_dict()
        with self.lock:
            self.alerts.append(d)
            aid = a.details.get("id")
            if isinstance(aid, str):
                self.alert_owner[aid] = a.owner
            c = self.counts.setdefault(a.owner, {})
            c[a.type] = c.get(a.type, 0) + 1
            self._outbox.append(("alert", d))
            self._dirty.add("counts")

    def result(self, res: dict) -> None:
        """A command's result (CmdResult as a dict), pushed individually."""
        with self.lock:
            self._outbox.append(("result", res))

    def message(self, m) -> None:
        """One data message (decoded, checked): positions, tracks, confirmations, orders."""
        kind = m.KIND
        with self.lock:
            if kind == "location":
                self.entity_pos[m.entity] = (m.lon, m.lat)
                self._dirty.add("positions")
            elif kind == "uv-state":
                self.entity_pos[m.robot] = (m.lon, m.lat)
                self._dirty.add("positions")
            elif kind == "track":
                self.tracks[m.track] = (m.lon, m.lat, m.strength, m.t)
                self._dirty.add("tracks")
            elif kind == "uv-sighting":
                self.tracks[m.target] = (m.lon, m.lat, 1, m.t)
                self._dirty.add("tracks")
            elif kind in ("cff", "cff-confirm"):
                self.cffs.add(m.cff)
            elif kind == "reorg":
                self._resubordinate(m.unit, m.new_parent)
            elif self.missions.take(m):
                self._dirty.add("missions")

    def _resubordinate(self, unit: str, parent: str) -> None:
        try:
            self.taskorg.resubordinate(unit, parent)
        except (KeyError, ValueError):
            return
        self._dirty |= {"positions", "org"}

    def silenced(self, unit: str, cmd, ok: bool) -> None:
        """A silence (or unsilence) command this console sent and its answer: the page
        lists the silences in force, to lift them."""
        with self.lock:
            if not ok:
                return
            if hasattr(cmd, "until_t"):
                self.silences[cmd.id] = {"id": cmd.id, "unit": unit, "types": list(cmd.types),
                                         "subjects": list(cmd.subjects), "areas": list(cmd.areas),
                                         "until_t": cmd.until_t, "comment": cmd.comment}
            else:
                self.silences.pop(cmd.id, None)
            self._dirty.add("silences")

    @property
    def actors(self) -> list[str]:
        """The units whose EAs this console may command now."""
        if self._fixed is not None:
            return list(self._fixed)
        return sorted(u for u in self.taskorg.subtree(self.unit) if u in self._eligible)

    def _silences(self) -> list[dict]:
        for k in [k for k, v in self.silences.items() if v["until_t"] <= self.t]:
            del self.silences[k]   # expired: the EA no longer applies it either
        return sorted(self.silences.values(), key=lambda v: v["until_t"])

    # -- outputs ------------------------------------------------------------------------
    def known_alert(self, aid: str) -> str | None:
        """The owner of alert `aid`, or None when the console never saw it."""
        with self.lock:
            return self.alert_owner.get(aid)

    def known_cff(self, cff: str) -> bool:
        with self.lock:
            return cff in self.cffs

    def _positions(self) -> dict[str, list[float]]:
        """Each unit's centroid: the mean of the latest positions of every entity in its subtree."""
        cs = self.taskorg.centroids(self.entity_pos)
        return {u: [round(lon, 6), round(lat, 6)] for u, (lon, lat, _) in cs.items()}

    def _tracks(self) -> dict[str, list]:
        old = self.t - TRACK_TTL_S
        for k in [k for k, v in self.tracks.items() if v[3] < old]:
            del self.tracks[k]
        return {k: [round(v[0], 6), round(v[1], 6), v[2]] for k, v in sorted(self.tracks.items())}

    def _units(self) -> dict[str, dict]:
        to, ms = self.taskorg, self.missions.current(self.t)
        return {u.id: {"name": u.name, "kind": u.kind, "parent": to.parent.get(u.id),
                       **ms.get(u.id, {"mission": None, "mission_type": None, "state": None})}
                for u in to.units.values()}

    def snapshot(self) -> dict:
        """GET /api/state."""
        with self.lock:
            return {"scenario": self.sc.name, "unit": self.unit, "units": self._units(),
                    "overlay": self.overlay, "positions": self._positions(), "tracks": self._tracks(),
                    "alerts": list(self.alerts), "counts": {o: dict(c) for o, c in sorted(self.counts.items())},
                    "t": self.t, "actors": self.actors, "silences": self._silences()}

    def drain(self) -> list[tuple[str, Any]]:
        """Events since the last drain: alerts and results one by one, then one
        clock/positions/tracks/missions/counts each when they changed."""
        with self.lock:
            out = list(self._outbox)
            self._outbox.clear()
            dirty, self._dirty = self._dirty, set()
            if "clock" in dirty:
                out.append(("clock", {"t": self.t, "ticks": [[t, round(w, 4)] for t, w in self._ticks]}))
                self._ticks.clear()
            if "positions" in dirty:
                out.append(("positions", self._positions()))
            if "tracks" in dirty or "clock" in dirty and self.tracks:
                n = len(self.tracks)
                tr = self._tracks()   # expires old ones: a change to send too
                if "tracks" in dirty or len(tr) != n:
                    out.append(("tracks", tr))
            if dirty & {"clock", "missions"}:
                ms = self.missions.current(self.t)
                if ms != self._sent_missions:
                    self._sent_missions = ms
                    out.append(("missions", ms))
            if "org" in dirty:
                out.append(("org", {"parents": dict(self.taskorg.parent), "actors": self.actors}))
            if "silences" in dirty or "clock" in dirty and self.silences:
                n = len(self.silences)
                ss = self._silences()
                if "silences" in dirty or len(ss) != n:
                    out.append(("silences", ss))
            if "counts" in dirty:
                out.append(("counts", {o: dict(c) for o, c in sorted(self.counts.items())}))
            return out
