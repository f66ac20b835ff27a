"""An EA's input journal on the live mesh: every frame it took, as received, and every
loss decision, in the order it made them. Replaying it (`replay`) gives the live run's
alerts exactly: whatever the wall clock did (a silence that became a loss), the journal
says what the EA decided and when in its input (../shared/notes/live-mesh.md: idleness
detected by wall clock is not reproducible, a decision written down is).

Records are msgpack arrays, each prefixed by its length (4 bytes, big-endian), flushed
as written (frames: before the next thing the peer tells anyone, see `frame`):
["frame", payload], ["lost", source, released, why], ["dir", by, kind, body] (a directive:
saim_mesh/authority/directives.py), ["cmd", t, kind, body] (a commander's command, taken at event
time t: a rebuilt or restarted EA takes it again at t), ["peer", unit, up] (another EA left
without a goodbye, or came back) or ["back", source]. A half-written last record (a kill) is ignored on reading, and
cut off when the journal is opened again, so that what a restart appends can be read."""
from __future__ import annotations

import struct
from pathlib import Path

import msgspec

_ENC = msgspec.msgpack.Encoder()
_LEN = struct.Struct(">I")


class InputJournal:
    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.n = 0   # records in the file: the index the next one gets
        end = 0
        if self.path.exists():
            self.n, end = _whole(self.path.read_bytes())
        self.f = open(self.path, "ab")
        if end < self.f.tell():   # a record cut by a kill: what follows it would not be read
            self.f.truncate(end)
            self.f.seek(end)

    def _write(self, rec: list, flush: bool = True) -> None:
        b = _ENC.encode(rec)
        self.f.write(_LEN.pack(len(b)) + b)
        self.n += 1
        if flush:
            self.f.flush()

    def frame(self, payload: bytes) -> None:
        """A frame taken: buffered (a write per frame cost more than its decoding), and on
        disk at the next `flush`, which the peer calls before anything leaves it (an
        alert, a notice, a confirmation) and every few tens of milliseconds: a kill loses
        at most frames that changed nothing outside, and a restart fetches them again."""
        self._write(["frame", payload], flush=False)

    def flush(self) -> None:
        self.f.flush()

    def lost(self, source: str, released: float, why: str) -> None:
        self._write(["lost", source, released, why])

    def directive(self, by: str, kind: str, body: bytes) -> None:
        """A directive taken (its body out of its envelope: checked when it came)."""
        self._write(["dir", by, kind, body])

    def command(self, t: float, kind: str, body: bytes) -> None:
        """A commander's command applied at event time `t` (its body out of its envelope:
        checked, signature and authority, when it came)."""
        self._write(["cmd", t, kind, body])

    def peer(self, unit: str, up: bool) -> None:
        """Another EA left the mesh without a goodbye, or came back (`LivePeer._alive`)."""
        self._write(["peer", unit, up])

    def back(self, source: str) -> None:
        """A lost source was heard again here: the EA was rebuilt (`LivePeer.back`)."""
        self._write(["back", source])

    def close(self) -> None:
        self.f.close()


def _spans(data: bytes):
    """(start, end) of each whole record's body at the start of `data` (a record cut by a
    kill ends it)."""
    i = 0
    while i + 4 <= len(data):
        (n,) = _LEN.unpack_from(data, i)
        if i + 4 + n > len(data):
            return
        yield i + 4, i + 4 + n
        i += 4 + n


def _whole(data: bytes) -> tuple[int, int]:
    """The whole records at the start of `data`: how many, and where they end."""
    n, end = 0, 0
    for _, end in _spans(data):
        n += 1
    return n, end


def records(path: str | Path) -> list[list]:
    data = Path(path).read_bytes()
    return [msgspec.msgpack.decode(data[a:b]) for a, b in _spans(data)]


def replay(peer, path: str | Path) -> list:
    """Feed a fresh `LivePeer` (not running: no session) the journal's records; the alerts
    it gives. The peer's own journal and logs should be off (out_path None). A source's
    return rebuilds the EA from the records before it, as it did live."""
    peer.history = []
    for rec in records(path):
        peer.replay_record(rec)
        peer.history.append(rec)
    peer.at_record = None
    peer.ea.finish(peer.end_t())
    return peer.given
