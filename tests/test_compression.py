"""Send less across the radio (issue 32, item 5): every saim-mesh Zenoh session compresses
its unicast links (configs/zenoh-peer.json5), so a command post's frames of location
reports take about half the bytes on the wire, with nothing changed in what arrives.

Measured through a counting TCP proxy (net/linkemu.Link) between two sessions made by
`zenoh_config.config`, once with compression and once without, on the same frames: cp.A's share
of the battalion's battle (its first 10 minutes), one frame per epoch (about 700 bytes) as a
live source sends them. Measured 1.75x fewer bytes; smaller frames gain less (the small
battle's 170-byte frames: 1.13x), a brigade battalion's larger ones more."""
from __future__ import annotations

import math
import queue
import time

import pytest
import zenoh

from saim_mesh.protocol import messages as M
from saim_mesh import scenario as S
from saim_mesh.authority.commands import _wait_matching
from saim_mesh.live import frames as F
from saim_mesh.live.play import EPOCH_S, share
from saim_mesh.net.linkemu import Link
from saim_mesh.launch.zenoh_config import config, free_port

from .conftest import BATTALION

pytestmark = pytest.mark.timeout(120)
FRAMES = 300


def epoch_frames(n: int) -> list[bytes]:
    """cp.A's first `n` frames: its messages grouped by epoch, numbered, with watermarks."""
    sc = S.load(BATTALION)
    by: dict[float, list[bytes]] = {}
    for m in share(sc, ["A"], False):
        by.setdefault(math.ceil(m.t / EPOCH_S) * EPOCH_S, []).append(M.encode(m))
    out = []
    for seq, (end, msgs) in enumerate(sorted(by.items())[:n], start=1):
        out.append(F.encode(F.Frame(v=1, source="cp.A", epoch=1, seq=seq, wm=end - EPOCH_S, msgs=msgs)))
    return out


def session(compress: bool, **endpoints) -> zenoh.Session:
    conf = config(**endpoints)
    if not compress:
        conf.insert_json5("transport/unicast/compression/enabled", "false")
    return zenoh.open(conf)


def through_a_link(payloads: list[bytes], compress: bool) -> tuple[int, list[bytes]]:
    """Bytes the publisher's side put on the wire for `payloads`, and what arrived."""
    port, front = free_port(), free_port()
    got: queue.SimpleQueue = queue.SimpleQueue()
    with Link(front, port) as link, session(compress, listen=[f"tcp/127.0.0.1:{port}"]) as rx:
        rx.declare_subscriber("test/src/cp.A", lambda s: got.put(s.payload.to_bytes()))
        with session(compress, connect=[f"tcp/127.0.0.1:{front}"], listen=[]) as tx:
            pub = tx.declare_publisher("test/src/cp.A")
            assert _wait_matching(pub, time.monotonic() + 30), "the subscriber never matched"
            before = link.stats()["up"]["bytes"]
            arrived = []
            for p in payloads:   # one frame at a time, as a paced source sends them
                pub.put(p)
                arrived.append(got.get(timeout=10))
            return link.stats()["up"]["bytes"] - before, arrived


def test_frames_cross_a_link_compressed_and_arrive_unchanged():
    frames = epoch_frames(FRAMES)
    raw = sum(len(f) for f in frames)
    assert len(frames) == FRAMES and raw > 150_000
    plain, got_plain = through_a_link(frames, compress=False)
    packed, got_packed = through_a_link(frames, compress=True)
    assert got_plain == frames and got_packed == frames   # the same bytes arrive, in order
    assert plain >= raw                                    # uncompressed: at least the payloads
    assert packed < 0.7 * plain, (packed, plain, raw)      # compressed: well under
