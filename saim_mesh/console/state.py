"""The console's model of the battle: what the commander's page shows, fed from the
mesh (feed.py) or from in-process EAs, read by the web server (server.py).

Alerts are kept as given (the page folds them into stories by `details.story`); silenced
and inhibited ones apart (`quiet`: logged, never shown as new); re-notifications and
escalations (`notice`) are not alerts and never counted. The counts (Fig. 7) count every
alert an EA logged, quiet ones included, as `evaluate` counts the alert logs.

Pure Python (no Zenoh, no asyncio): every input is a decoded message or alert, so it
is unit-testable. Thread-safe: the feed thread writes, the server's loop reads. High-rate
inputs (positions, tracks, the clock) only mark the model dirty; `drain()` (called at
most every 100 ms by the server) turns what changed into events, so 2,500 location
reports a second cost a dict update each, not a browser update each.
"""
from __future__ import annotations

import threading
from collections import OrderedDict, deque
from typing import Any

from ea_agent import domains

from .missions import Missions
from .overlay import overlay_geojson

MAX_ALERTS = 5000          # shown alerts kept for the snapshot (ids are kept for all)
MAX_QUIET = 2000           # silenced or inhibited alerts kept for the snapshot (the newest)
MAX_NOTICES = 2000         # re-notifications and escalations kept for the snapshot (the newest)
MAX_BY_ID = 20_000         # alerts kept by id for GET /api/alert (the newest)
MAX_OUTBOX = 10_000        # alerts/results waiting for the next drain (no server running)
TRACK_TTL_S = 600.0        # a track not reported for this long leaves the picture


def quiet(d: dict) -> bool:
    """A silenced or inhibited alert (as JSON): logged and published, never shown as new."""
    det = d.get("details") or {}
    return bool(det.get("silenced")) or bool(det.get("inhibited_by"))


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
        self.inhibits: dict[tuple[str, str], dict] = {}   # inhibition rules it made, by (unit, id)
        self._expiries: dict[str, float] = {}
        self.lock = threading.Lock()
        self.t = 0.0
        self.ended = False
        self.alerts: deque[dict] = deque(maxlen=MAX_ALERTS)   # shown (neither silenced nor inhibited)
        self.quiet: deque[dict] = deque(maxlen=MAX_QUIET)     # silenced or inhibited: logged, not shown as new
        self.notices: deque[dict] = deque(maxlen=MAX_NOTICES)
        self.alert_owner: dict[str, str] = {}       # alert id -> owner (every alert seen)
        self.by_id: OrderedDict[str, dict] = OrderedDict()   # the newest MAX_BY_ID alerts, by id
        self.acked: OrderedDict[str, float] = OrderedDict()   # alert id -> when an ack (or decision) took effect
        self.counts: dict[str, dict[str, int]] = {}
        self.entity_pos: dict[str, tuple[float, float]] = {}
        self.tracks: dict[str, tuple[float, float, int, float]] = {}   # id -> lon, lat, strength, t
        self.cffs: dict[str, object] = {}   # call for fire id -> its message (the newest 10,000)
        self.missions = Missions(sc, self.taskorg)
        self.overlay = overlay_geojson(sc)
        self._outbox: deque[tuple[str, Any]] = deque(maxlen=MAX_OUTBOX)
        self._dirty: set[str] = set()
        self._sent_missions: dict | None = None
        self._ticks: deque[tuple[float, float]] = deque(maxlen=MAX_OUTBOX)   # (t, wall) since the last drain

    # -- inputs (any thread) ----------------------------------------------------------
    def clock(self, t: float, end: bool = False, w: float | None = None) -> None:
        """The mesh clock reached `t`; `w`: the wall time the console heard it (passed on to
        the page, which measures raise-to-render latency against it)."""
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
        """One alert (an `Alert`): pushed individually, counted per owner and type. A
        silenced or inhibited one (`details.silenced`, `details.inhibited_by`) is kept
        apart (`quiet`): the page shows it in its quiet view only; it still counts, as
        every logged alert does (the Fig. 7 table counts the EA's alert log)."""
        d = a.to_json_dict()
        with self.lock:
            (self.quiet if quiet(d) else self.alerts).append(d)
            aid = a.details.get("id")
            if isinstance(aid, str):
                self.alert_owner[aid] = a.owner
                self.by_id[aid] = d
                self.by_id.move_to_end(aid)
                if len(self.by_id) > MAX_BY_ID:
                    self.by_id.popitem(last=False)
            c = self.counts.setdefault(a.owner, {})
            c[a.type] = c.get(a.type, 0) + 1
            self._outbox.append(("alert", d))
            self._dirty.add("counts")

    def notice(self, n: dict) -> None:
        """A re-notification or escalation (`Notice.to_json_dict()`): pushed individually
        (event `notice`), the newest kept for the snapshot. Not an alert: never counted."""
        with self.lock:
            self.notices.append(n)
            self._outbox.append(("notice", n))

    def result(self, res: dict) -> None:
        """A command's result (CmdResult as a dict), pushed individually. An alert
        acknowledged (or decided) by any console is remembered: a page opened later does
        not show it as waiting for an answer."""
        with self.lock:
            self._outbox.append(("result", res))
            ref = res.get("ref")
            if res.get("ok") and res.get("kind") in ("ack", "decide") and isinstance(ref, str) and ref:
                self.acked[ref] = res.get("t") or self.t
                if len(self.acked) > MAX_BY_ID:
                    self.acked.popitem(last=False)

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
                self.cffs[m.cff] = m
                if len(self.cffs) > 10_000:
                    del self.cffs[next(iter(self.cffs))]
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

    def inhibited(self, unit: str, cmd, ok: bool) -> None:
        """An inhibit (or uninhibit) command this console sent and its answer: the page
        lists the rules in force that it made, to lift them. A rule stays in force until
        lifted (`for_s` is how long a source alert inhibits, not the rule's life)."""
        with self.lock:
            if not ok:
                return
            if hasattr(cmd, "source"):
                spec = lambda m: {k: list(getattr(m, k)) for k in ("types", "subjects", "priorities", "owners")  # noqa: E731
                                  if getattr(m, k)}
                self.inhibits[(unit, cmd.id)] = {"id": cmd.id, "unit": unit, "source": spec(cmd.source),
                                                 "target": spec(cmd.target), "equal": list(cmd.equal),
                                                 "for_s": cmd.for_s, "comment": cmd.comment, "t": self.t,
                                                 "active_s": cmd.for_s or self._expiry(unit)}
            else:
                self.inhibits.pop((unit, cmd.id), None)
            self._dirty.add("inhibits")

    def _expiry(self, unit: str) -> float:
        """`unit`'s voa.expiry_s as its domain's config gives it: how long a source alert
        keeps a rule with for_s 0 active (the page's view of what the rule covers now)."""
        if unit not in self._expiries:
            try:
                from ..inprocess.runner import config_for
                self._expiries[unit] = float(config_for(self.sc, unit)["voa"]["expiry_s"])
            except Exception:   # a config that does not load here: the EA's default
                self._expiries[unit] = 720.0
        return self._expiries[unit]

    def _inhibits(self) -> list[dict]:
        return [self.inhibits[k] for k in sorted(self.inhibits)]

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

    def find_alert(self, aid: str) -> dict | None:
        """Alert `aid` as the page gets it (among the newest MAX_BY_ID), or None."""
        with self.lock:
            return self.by_id.get(aid)

    def known_inhibit(self, unit: str, rid: str) -> bool:
        with self.lock:
            return (unit, rid) in self.inhibits

    def inhibit_ids(self, unit: str) -> list[str]:
        """The rules in force on `unit`'s EA that this console made."""
        with self.lock:
            return sorted(i for u, i in self.inhibits if u == unit)

    def known_cff(self, cff: str) -> bool:
        with self.lock:
            return cff in self.cffs

    def cff_message(self, cff: str):
        """The call for fire as this console heard it (None: not heard)."""
        with self.lock:
            return self.cffs.get(cff)

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
                    "t": self.t, "actors": self.actors, "silences": self._silences(),
                    "quiet": list(self.quiet), "notices": list(self.notices), "inhibits": self._inhibits(),
                    "acked": list(self.acked)}

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
            if "inhibits" in dirty:
                out.append(("inhibits", self._inhibits()))
            if "counts" in dirty:
                out.append(("counts", {o: dict(c) for o, c in sorted(self.counts.items())}))
            return out
