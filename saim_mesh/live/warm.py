"""The live peer warmed up with no Zenoh session: the first half hour of a recorded
scenario as its sources publish it (`play.of_share` and `play.publish`, the frames cut
and encoded by `LiveSource` itself), taken by a `LivePeer` through the path a frame off
the wire takes (`receive`: decoding, its source's sequence, the gate, the event-time
order, the EA, the alert log and the input journal).

The zygote runs it before it forks (saim_mesh/launch/zygote.py): what this code builds on first
use (msgspec's per-type codecs, the interpreter's specialised bytecode, the EA's
detectors, shapely's and the domain's first-use state, modules imported on first use)
then exists once, in pages every EA peer shares, instead of once in each of them.
The frames are cut on event time only (every epoch's watermark flushes), so the same
scenario warms the same way on any machine."""
from __future__ import annotations

import heapq
import tempfile
from pathlib import Path

import zenoh

from dissemination.keyspace import KeySpace

from . import frames as F
from . import play
from .depend import cp_shares
from .peer import LivePeer
from .source import FRAME_BYTES, LiveSource

WARM_S = 1800.0   # event time warmed: far enough that most detectors raise alerts (the alert log, the
# notifier), short enough that the zygote is ready long before the mesh needs its peers


class _Pub:
    """Where a `_Frames` source's frames go instead of a Zenoh publisher."""

    def __init__(self):
        self.out: list[bytes] = []

    def put(self, payload: bytes) -> None:
        self.out.append(payload)


class _Frames(LiveSource):
    """A source's frames, cut and encoded by `LiveSource`'s own code, kept in a list:
    no session, no cache, no journal. Every watermark flushes (no wall-clock linger), so
    the frames depend on the stream alone."""

    def __init__(self, ks: KeySpace, name: str):   # not LiveSource's: it declares on a session
        self.name, self.ks = name, ks
        self.epoch, self.seq, self.wm = 1, 0, -1.0
        self.frame_bytes = FRAME_BYTES
        self.pending, self.size = [], 0
        self.last_sent, self.sent = 0.0, 0
        self.journal = self.queryable = None
        self.published_before, self.resumed_epoch = 0, 0
        self.pub = _Pub()

    def watermark(self, t: float, linger: bool = False) -> None:
        super().watermark(t, linger=False)


def source_frames(sc, root: str, until: float = WARM_S) -> list[tuple[str, bytes]]:
    """Every source's frames (`depend.cp_shares`) up to event time `until`, as (key,
    payload), merged across sources by watermark (then name): roughly as they arrive."""
    ks = KeySpace.of(sc, root)
    per: list[list[tuple[float, str, int, str, bytes]]] = []
    for name, sh in cp_shares(sc).items():
        src = _Frames(ks, name)
        play.publish(src, play.of_share(sc, sh), until=until, log=lambda *a, **k: None)
        # the watermark each frame carries, read back as a receiver reads it
        per.append([(F.decode(b, 1 << 30).wm, name, i, ks.src(name), b) for i, b in enumerate(src.pub.out)])
    return [(key, b) for _, _, _, key, b in heapq.merge(*per)]


def warm(scenario: str | Path, unit: str | None = None, until: float = WARM_S) -> int:
    """A fresh `LivePeer` for `unit` (default: the top unit, whose EA depends on every
    source) takes the first `until` seconds of `scenario`'s sources; its logs go to a
    temporary directory, removed after. Returns the messages its EA took in."""
    from .. import scenario as S
    sc = S.load(scenario)
    root = f"saim/{sc.name}/live"
    unit = unit or sc.taskorg.root
    todo = source_frames(sc, root, until)
    with tempfile.TemporaryDirectory(prefix="saim-warm-") as tmp:
        p = LivePeer(sc, unit, zenoh.Config(), root, list(cp_shares(sc)), str(Path(tmp) / f"{unit}.jsonl"),
                     log=lambda *a, **k: None)
        try:
            p.join()   # as a fresh peer joins the mesh (`serve`)
            for key, payload in todo:
                p.receive(payload, key)
            p.out.inputs_on_disk()
        finally:
            p.out.close()
    return p.ea.n_in
