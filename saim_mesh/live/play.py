"""What a source publishes: a command post's share of a recorded scenario (the units of
its subtree, optionally the hostile tracks it sees), or reports read from a file or
standard input (JSON lines of messages, NMEA or GPX), in event time with a watermark
every epoch; paced at a speed, as fast as possible, or live (event time = wall clock
from a start instant)."""
from __future__ import annotations

import json
import math
import sys
import time
import xml.etree.ElementTree as ET
from datetime import datetime, timezone
from typing import IO, Iterable, Iterator

from ..protocol import messages as M
from .source import LiveSource

EPOCH_S = 2.0


def of_share(sc, sh) -> Iterator[M.Message]:
    """What one of a scenario's sources publishes (`depend.cp_shares`)."""
    if sh.fusion is not None:
        return fused(sc, [sh.fusion])
    return share(sc, list(sh.units) if sh.units is not None else None, sh.tracks, list(sh.but))


def fused(sc, names: list[str]) -> Iterator[M.Message]:
    """The tracks the named sensor groups' fusion nodes give from their sensors' hits:
    the nodes as in process (`runner.Fusion`), flushed on every event's time as there."""
    from ..inprocess.runner import Fusion
    groups = sc.meta.get("fusion", {}).get("groups", {})
    for g in names:
        if g not in groups:
            raise KeyError(f"unknown fusion group {g!r}: not in {sc.name}'s scenario.json "
                           f"({', '.join(sorted(groups)) or 'none'})")
    fusion = Fusion(sc, {g: groups[g] for g in names})
    for ev in sc.events:
        yield from fusion.feed(ev)
    yield from fusion.flush(sc.duration_s)   # windows that close after the last event


def share(sc, units: list[str] | None, tracks: bool, but: list[str] = ()) -> Iterator[M.Message]:
    """The scenario's events that originate in `units`' subtrees (every unit when None)
    except `but`'s subtrees (another command post publishes those): their members'
    positions, their confirmations, calls for fire and orders they issue; hostile tracks
    only with `tracks` (the tracks the scenario gives; where it has sensor groups, each
    group's fusion node is its own source: `fused`)."""
    from ea_agent import domains

    to = sc.taskorg
    source_of = getattr(domains.of(sc), "source_of", None)   # a robot's own radio sends its state
    mine = set().union(*(to.subtree(u) for u in units)) if units else set(to.units)
    for u in but:
        mine -= set(to.subtree(u))
    for ev in sc.events:
        k = type(ev)
        if k is M.SensorHit:   # raw hits never leave: each group's fusion node is its own source
            continue
        if k is M.LocationReport:
            if to.entity_unit.get(ev.entity) in mine:
                yield ev
        elif k is M.SensorTrack:
            if tracks:
                yield ev
        elif k is M.MissionConfirm:
            if ev.unit in mine:
                yield ev
        elif k in (M.CallForFire, M.CallForFireConfirm):
            if ev.requester in mine:
                yield ev
        elif k is M.Order:
            if ev.issuer in mine:
                yield ev
        elif k is M.Reorganization:
            if units is None or ev.new_parent in mine:
                yield ev
        elif source_of is not None and source_of(ev) in mine:
            yield ev


def read_lines(f: IO[str], fmt: str, entity: str | None, start: float | None) -> Iterator[M.Message]:
    """Reports from a file: `jsonl` (messages as the scenario's events are written), `nmea`
    (GGA/RMC sentences of one `entity`) or `gpx` (track points of one `entity`); NMEA and GPX
    times are UTC, turned into event time from `start` (epoch seconds)."""
    if fmt == "jsonl":
        for i, line in enumerate(f, 1):
            if line.strip():
                try:
                    yield M.from_dict(json.loads(line))
                except (ValueError, M.MessageError) as e:
                    print(f"line {i}: skipped: {e}", file=sys.stderr, flush=True)
        return
    if entity is None:
        raise ValueError(f"--format {fmt}: --entity names whose reports these are")
    base = start if start is not None else time.time()
    if fmt == "gpx":
        root = ET.parse(f).getroot()
        for pt in root.iter():
            if pt.tag.endswith("trkpt") or pt.tag.endswith("wpt"):
                when = next((c.text for c in pt if c.tag.endswith("time")), None)
                if when is None:
                    continue
                t = datetime.fromisoformat(when.replace("Z", "+00:00")).timestamp() - base
                yield M.LocationReport(round(t, 3), entity, float(pt.get("lon")), float(pt.get("lat")))
        return
    day = datetime.fromtimestamp(base, timezone.utc).replace(hour=0, minute=0, second=0, microsecond=0)
    for line in f:
        p = line.strip().split("*", 1)[0].split(",")
        if not p or len(p[0]) < 6 or p[0][3:6] not in ("GGA", "RMC"):
            continue
        try:
            hhmmss = p[1]
            lat, ns, lon, ew = (p[2], p[3], p[4], p[5]) if p[0][3:6] == "GGA" else (p[3], p[4], p[5], p[6])
            t = (day.timestamp() + int(hhmmss[:2]) * 3600 + int(hhmmss[2:4]) * 60 + float(hhmmss[4:])) - base
            la = (int(lat[:2]) + float(lat[2:]) / 60) * (1 if ns == "N" else -1)
            lo = (int(lon[:3]) + float(lon[3:]) / 60) * (1 if ew == "E" else -1)
        except (ValueError, IndexError):
            print(f"skipped an NMEA sentence: {line.strip()[:60]}", file=sys.stderr, flush=True)
            continue
        yield M.LocationReport(round(t, 3), entity, lo, la)


def publish(src: LiveSource, msgs: Iterable[M.Message], speed: float | None = None, live_start: float | None = None,
            epoch_s: float = EPOCH_S, log=print, until: float | None = None, paced_from: float | None = None,
            pace=None) -> int:
    """Publish `msgs` (in event-time order) with a watermark at every epoch boundary they
    pass; at `speed` x real time, as fast as possible (None), or live (wait until each
    message's event time on the wall clock, and keep watermarks going while idle).
    `paced_from`: with a speed, the wall time of event time 0 (several sources in step).
    `pace` (a `pace.SourcePace`, as fast as possible only): never further ahead of the
    slowest EA depending on this source than it allows."""
    t0 = time.monotonic() if paced_from is None else time.monotonic() - (time.time() - paced_from)
    clock = None   # event time now, and how to sleep until an event time
    if live_start is not None:
        clock = (lambda: time.time() - live_start, lambda t: t - (time.time() - live_start))
    elif speed:
        clock = (lambda: (time.monotonic() - t0) * speed, lambda t: (t0 + t / speed) - time.monotonic())
    n = 0
    last_wm = src.wm
    next_say = 600.0
    skip = getattr(src, "published_before", 0)
    if skip:
        log(f"source {src.name}: resumed after the {skip} messages epoch {src.resumed_epoch} published "
            f"(watermark {src.wm})", flush=True)
    for m in msgs:
        if skip:   # a restart: these went out before (receivers have them, or fetch them from the journal)
            skip -= 1
            continue
        if until is not None and m.t > until:
            break
        if m.t >= next_say:   # progress, for whoever watches the source's log
            log(f"source {src.name} t={next_say:.0f} messages={n}", flush=True)
            next_say = (math.floor(m.t / 600.0) + 1) * 600.0
        if not math.isfinite(m.t) or m.t <= src.wm:
            log(f"source {src.name}: skipped a {m.KIND} at t={m.t} (not after its watermark {src.wm})", flush=True)
            continue
        if clock is not None:   # live or paced: promise each epoch as its clock passes it
            last_wm = _idle(src, clock, m.t, epoch_s, last_wm)
        w = math.ceil(m.t / epoch_s) * epoch_s - epoch_s   # the last boundary strictly before m.t
        if clock is None and pace is not None:   # what is held goes out before it waits
            pace.wait(m.t, lambda: src.watermark(max(w, last_wm)), beat=src.heartbeat)
        if w > last_wm:
            src.watermark(w, linger=clock is None)   # as fast as possible: fuller frames
            last_wm = w
        try:
            src.put(m)
        except (ValueError, M.MessageError) as e:   # one line, counted, and the source goes on
            log(f"source {src.name}: skipped a {getattr(m, 'KIND', '?')} at t={m.t}: {e}", flush=True)
            continue
        n += 1
    if until is not None:   # the stream ends at `until`: live, keep promising epochs as the wall clock passes them
        if clock is not None:
            _idle(src, clock, until, epoch_s, last_wm, inclusive=True)
        src.watermark(until)
    return n


def _idle(src: LiveSource, clock, t: float, epoch_s: float, last_wm: float, inclusive: bool = False) -> float:
    """Nothing to send before event time `t`: promise each epoch boundary as the clock
    (live: the wall clock; paced: event time at the speed) passes it (a silent source would
    be declared lost), waking exactly at each one. Returns the last watermark given."""
    now_of, wait_for = clock
    while (now := now_of()) < t:
        w = math.floor(now / epoch_s) * epoch_s
        if w > last_wm and (w < t or inclusive and w <= t):
            src.watermark(w)
            last_wm = w
        nxt = (math.floor(now / epoch_s) + 1) * epoch_s
        time.sleep(max(0.0, wait_for(min(t, nxt))))
    return last_wm
