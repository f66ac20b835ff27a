"""A source replaying as fast as possible lingers: its watermarks ride on fuller frames,
at most `LINGER_S` of wall time late, and every message still goes out once, in order,
after the watermark its frame's predecessor promised (issue 31: CPU per event)."""
from __future__ import annotations

import math
import uuid

import pytest
import zenoh

from dissemination.keyspace import KeySpace
from saim_mesh.protocol import messages as M
from saim_mesh import scenario as S
from saim_mesh.live import frames as F
from saim_mesh.live import play
from saim_mesh.live import source as SRC
from saim_mesh.launch.zenoh_config import config

from .conftest import SMALL


class Wire:
    """Stands in for the advanced publisher: keeps what was put."""

    def __init__(self):
        self.frames: list[F.Frame] = []

    def put(self, payload: bytes) -> None:
        self.frames.append(F.decode(payload, 1 << 20))

    def undeclare(self) -> None:
        pass


@pytest.fixture(scope="module")
def reports():
    sc = S.load(SMALL)
    return sc, [e for e in sc.events if type(e) is M.LocationReport][:3000]


def published(sc, msgs, monkeypatch, linger_s: float) -> list[F.Frame]:
    monkeypatch.setattr(SRC, "LINGER_S", linger_s)
    with zenoh.open(config(["tcp/127.0.0.1:0"], None)) as s:
        src = SRC.LiveSource(s, KeySpace.of(sc, f"test/{uuid.uuid4().hex[:8]}"), "cp.test")
        src.pub.undeclare()
        src.pub = wire = Wire()
        assert play.publish(src, msgs, speed=None, log=lambda *a, **k: None) == len(msgs)
        src.close()
    return wire.frames


def check_stream(frames: list[F.Frame], msgs) -> None:
    """Every message once, in order; each frame's messages after the watermark before it."""
    got = [M.decode(b) for f in frames for b in f.msgs]
    assert got == list(msgs)
    wm = -math.inf
    for f in frames:
        assert all(M.decode(b).t > wm for b in f.msgs)
        assert f.wm >= wm
        wm = f.wm
    assert frames[-1].end and [f.seq for f in frames] == list(range(1, len(frames) + 1))


def test_a_fast_replay_sends_fuller_frames_with_the_same_stream(reports, monkeypatch):
    sc, msgs = reports
    epochs = len({math.ceil(m.t / play.EPOCH_S) for m in msgs})
    every_epoch = published(sc, msgs, monkeypatch, 0.0)     # no lingering: a frame per epoch boundary
    lingering = published(sc, msgs, monkeypatch, 3600.0)    # only a full frame or the end goes out
    check_stream(every_epoch, msgs)
    check_stream(lingering, msgs)
    assert len(every_epoch) >= epochs - 1
    size = max(sum(len(b) for b in f.msgs) for f in lingering)
    assert len(lingering) <= len(every_epoch) // 10 and size > SRC.FRAME_BYTES // 2


def test_a_lingering_watermark_is_held_at_most_linger_s(reports, monkeypatch):
    """With the wall clock moving past `LINGER_S` between epochs, the source says each
    watermark at once, as a paced one does: nobody waits on it long enough to call it silent."""
    sc, msgs = reports
    now = [0.0]

    def tick():
        now[0] += 1.0
        return now[0]
    monkeypatch.setattr(SRC.time, "monotonic", tick)
    frames = published(sc, msgs, monkeypatch, 0.5)
    check_stream(frames, msgs)
    epochs = len({math.ceil(m.t / play.EPOCH_S) for m in msgs})
    assert len(frames) >= epochs - 1
