"""A source replaying as fast as possible goes no further than `LEAD_S` of event time
past the slowest EA that depends on it (its acks), flushes what it holds before it
waits, and is held by no EA it has not heard from for `STALE_S` (issue 31.2: flow
control, so a fast replay neither outruns its EAs nor loses frames between routers)."""
from __future__ import annotations

import math
import threading
import uuid

import pytest
import zenoh

from dissemination.keyspace import KeySpace
from saim_mesh.protocol import messages
from saim_mesh import scenario as scenarios
from saim_mesh.protocol import wire as wire_codec
from saim_mesh.live import pace as live_pace
from saim_mesh.live import play
from saim_mesh.live import source as live_source
from saim_mesh.launch.zenoh_config import config

from .conftest import SMALL
from .test_source_linger import Wire, check_stream


@pytest.fixture(scope="module")
def reports():
    sc = scenarios.load(SMALL)
    return sc, [e for e in sc.events if type(e) is messages.LocationReport][:3000]


def ack(s, ks, unit: str, t: float) -> None:
    s.put(ks.ack(unit, "cp.test"), wire_codec.encode(wire_codec.make(wire_codec.Ack, t=t)))


def release(pace: live_pace.SourcePace, th: threading.Thread) -> None:
    """Never leave the publishing thread waiting, whatever the test asserted."""
    pace.acks["stop"] = (math.inf, math.inf)
    with pace.cv:
        pace.cv.notify_all()
    th.join(30)


def published_all(src, pace, th, done: list, msgs) -> None:
    """The publishing thread ended having published every message; source and pace closed."""
    assert not th.is_alive() and done == [len(msgs)]
    src.close()
    pace.close()


def publishing(s, ks, msgs, **pace_args):
    """A source publishing `msgs` as fast as its pace lets it, on a thread, into a Wire
    that keeps its frames: (source, wire, pace, thread, [count published, once done])."""
    src = live_source.LiveSource(s, ks, "cp.test")
    src.pub.undeclare()
    src.pub = wire = Wire()
    pace = live_pace.SourcePace(s, ks, "cp.test", lead_s=60.0, stale_s=3600.0, first_s=3600.0,
                                log=lambda *a, **k: None, **pace_args)
    done: list = []
    th = threading.Thread(target=lambda: done.append(play.publish(src, msgs, speed=None, pace=pace,
                                                                    log=lambda *a, **k: None)))
    th.start()
    return src, wire, pace, th, done


def sent_upto(wire: Wire) -> float:
    return max((messages.decode(b).t for f in wire.frames for b in f.msgs), default=-math.inf)


@pytest.mark.timeout(60)
def test_a_fast_source_waits_for_its_slowest_ea(reports):
    sc, msgs = reports
    assert msgs[-1].t > 400
    with zenoh.open(config(["tcp/127.0.0.1:0"], None)) as s:
        ks = KeySpace.of(sc, f"test/{uuid.uuid4().hex[:8]}")
        src, wire, pace, th, done = publishing(s, ks, msgs)
        def blocked_beyond(x: float) -> None:
            with pace.cv:   # the source notifies when it starts waiting
                assert pace.cv.wait_for(lambda: pace.blocked.is_set() and pace.blocked_t > x, timeout=20)
        try:
            # no EA heard yet: the first LEAD_S only, all of it flushed (no lingering frame held back)
            blocked_beyond(60)
            assert 50 < sent_upto(wire) <= 60 and wire.frames[-1].wm >= 58
            ack(s, ks, "A1", 100.0)
            ack(s, ks, "A2", 200.0)
            blocked_beyond(160)   # the slowest (A1 at 100) holds it: up to 160
            assert 150 < sent_upto(wire) <= 160 and wire.frames[-1].wm >= 158
            ack(s, ks, "A1", 300.0)
            blocked_beyond(260)   # A2 (200) is now the slowest: up to 260
            assert 250 < sent_upto(wire) <= 260
            ack(s, ks, "A1", 1e6)
            ack(s, ks, "A2", 1e6)
            th.join(30)
        finally:
            release(pace, th)
        published_all(src, pace, th, done, msgs)
    check_stream(wire.frames, msgs)
    assert pace.waits >= 3


@pytest.mark.timeout(60)
def test_a_held_source_beats_so_no_ea_takes_it_for_a_silent_one(reports):
    """Held back by a slow EA for longer than an EA's `source_silence_s`, a source still
    says it is alive: an empty frame every `beat_s`, its watermark unchanged, nothing
    new promised and nothing lost from the stream."""
    sc, msgs = reports
    with zenoh.open(config(["tcp/127.0.0.1:0"], None)) as s:
        ks = KeySpace.of(sc, f"test/{uuid.uuid4().hex[:8]}")
        src, wire, pace, th, done = publishing(s, ks, msgs, beat_s=0.05)
        try:
            with pace.cv:   # held at 60 (nobody acked) and beating
                assert pace.cv.wait_for(lambda: pace.blocked.is_set() and pace.beats >= 3, timeout=20)
            held = list(wire.frames)
            flushed = max(i for i, f in enumerate(held) if f.msgs)
            beats = held[flushed + 1:]
            assert len(beats) >= 3 and all(not f.msgs and not f.end for f in beats)
            assert {f.wm for f in beats} == {held[flushed].wm} and held[flushed].wm <= 60.0
            ack(s, ks, "A1", 1e6)
            th.join(30)
        finally:
            release(pace, th)
        published_all(src, pace, th, done, msgs)
    check_stream(wire.frames, msgs)


def test_an_ea_not_heard_for_stale_s_holds_nobody(reports):
    sc, _ = reports
    with zenoh.open(config(["tcp/127.0.0.1:0"], None)) as s:
        ks = KeySpace.of(sc, f"test/{uuid.uuid4().hex[:8]}")
        pace = live_pace.SourcePace(s, ks, "cp.test", lead_s=60.0, stale_s=5.0, log=lambda *a, **k: None)
        assert pace.allowed() == 60.0          # nobody heard yet: the first lead only
        pace.acks = {"A1": (100.0, 1000.0), "A2": (400.0, 1003.0)}
        assert pace.allowed(now=1004.0) == 160.0    # both fresh: the slowest
        assert pace.allowed(now=1006.0) == 460.0    # A1 silent for 6 s (cut off, gone): A2 alone
        assert pace.allowed(now=1009.0) == math.inf  # nobody left: nothing holds it back
        pace.close()


def test_a_bad_ack_is_counted_not_taken(reports):
    sc, _ = reports
    said = []
    with zenoh.open(config(["tcp/127.0.0.1:0"], None)) as s:
        ks = KeySpace.of(sc, f"test/{uuid.uuid4().hex[:8]}")
        pace = live_pace.SourcePace(s, ks, "cp.test", log=lambda *a, **k: said.append(a[0]))
        s.put(ks.ack("A1", "cp.test"), b"\x93not an ack")
        s.put(ks.ack("A1", "cp.test"), wire_codec.encode(wire_codec.make(wire_codec.Ack, t=float("nan"))))
        ack(s, ks, "A2", 50.0)
        with pace.cv:
            assert pace.cv.wait_for(lambda: "A2" in pace.acks, timeout=10)
        assert "A1" not in pace.acks and pace.rejects.total == 2
        assert said and "ack" in said[0]
        pace.close()


def test_an_ea_acks_every_ack_every_s_of_event_time():
    class Session:
        def __init__(self):
            self.puts = []

        def put(self, key, payload):
            self.puts.append((key, wire_codec.decode_control(wire_codec.Ack, payload, 256).t))
    s, ks = Session(), KeySpace("test/x")
    prog = live_pace.EaProgress(ks, "A1", every_s=30.0)
    for t in (-math.inf, 0.0, 10.0, 29.9, 30.0, 45.0, 61.0, math.inf):
        prog.send(s, t, ["cp.a", "cp.b"])
    assert s.puts == [(ks.ack("A1", "cp.a"), 0.0), (ks.ack("A1", "cp.b"), 0.0),
                      (ks.ack("A1", "cp.a"), 30.0), (ks.ack("A1", "cp.b"), 30.0),
                      (ks.ack("A1", "cp.a"), 61.0), (ks.ack("A1", "cp.b"), 61.0)]
