"""A source's durable journal (issue 31.1): every frame it published, per epoch, in an
append-only file beside its epoch counter, served by a queryable on `srcj/<name>` for
catch-up beyond the advanced publisher's in-memory cache (a late joiner after a long
run, an EA that missed more than the cache holds, frames of an epoch before the source
restarted: the cache dies with the process, the file does not).

A query is a `JournalQuery` (epoch, first and last seq wanted); the answer is one reply
per frame held, in order, at most `MAX_FRAMES` and `MAX_BYTES` per query (ask again from
where it stopped). A query that cannot be read is answered with an error, and the source
lives on. Files: `<dir>/<name>.<epoch>.frames`, records length-prefixed (4 bytes,
big-endian); a half-written last record (a kill) is ignored on reading."""
from __future__ import annotations

import struct
import threading
from pathlib import Path

import msgspec
import zenoh

from .. import messages as M
from .. import wire as W

_LEN = struct.Struct(">I")
MAX_FRAMES = 2_000
MAX_BYTES = 16 * 2**20


class JournalQuery(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """Frames `lo`..`hi` (inclusive) of `epoch` of the queried source."""
    epoch: W.Seq
    lo: W.Seq
    hi: W.Seq


class SourceJournal:
    """Append-only frames of one source, indexed by (epoch, seq); thread-safe: the source
    appends, the queryable's callback reads."""

    def __init__(self, state_dir: str | Path, name: str, epoch: int):
        self.dir, self.name, self.epoch = Path(state_dir), name, epoch
        self.dir.mkdir(parents=True, exist_ok=True)
        self.lock = threading.Lock()
        self.f = open(self.path(epoch), "ab")
        self.index: dict[int, list[int]] = {epoch: []}   # epoch -> offset of seq 1, 2, ...
        self.served = 0
        self.errors = 0

    def path(self, epoch: int) -> Path:
        return self.dir / f"{self.name}.{epoch}.frames"

    def append(self, seq: int, payload: bytes) -> None:
        with self.lock:
            offs = self.index[self.epoch]
            if seq != len(offs) + 1:
                raise ValueError(f"source journal {self.name}: seq {seq} after {len(offs)}")
            offs.append(self.f.tell())
            self.f.write(_LEN.pack(len(payload)) + payload)
            self.f.flush()

    def _offsets(self, epoch: int) -> list[int]:
        """The index of an epoch (read from its file once, for an epoch before this start)."""
        offs = self.index.get(epoch)
        if offs is not None:
            return offs
        offs = []
        try:
            data = self.path(epoch).read_bytes()
        except OSError:
            data = b""
        i = 0
        while i + 4 <= len(data):
            (n,) = _LEN.unpack_from(data, i)
            if i + 4 + n > len(data):
                break
            offs.append(i)
            i += 4 + n
        self.index[epoch] = offs
        return offs

    def frames(self, epoch: int, lo: int, hi: int) -> list[bytes]:
        """Frames lo..hi of `epoch` held here (fewer at the bounds or past what is held)."""
        with self.lock:
            offs = self._offsets(epoch)
            lo, hi = max(lo, 1), min(hi, len(offs), lo + MAX_FRAMES - 1)
            if lo > hi:
                return []
            self.f.flush()
            out, size = [], 0
            with open(self.path(epoch), "rb") as r:
                for seq in range(lo, hi + 1):
                    r.seek(offs[seq - 1])
                    (n,) = _LEN.unpack(r.read(4))
                    b = r.read(n)
                    if len(b) != n or size + n > MAX_BYTES:
                        break
                    out.append(b)
                    size += n
            return out

    def serve(self, query, key: str) -> None:
        """Answer one query (a Zenoh queryable's callback): the frames, or an error."""
        try:
            raw = query.payload.to_bytes() if query.payload is not None else b""
            if len(raw) > 256:
                raise M.MessageError("journalquery", "(bytes)", f"{len(raw)} bytes, over 256")
            try:
                q = msgspec.msgpack.decode(raw, type=JournalQuery)
            except (msgspec.ValidationError, msgspec.DecodeError) as e:
                raise M.MessageError("journalquery", "(decode)", str(e)[:160]) from None
            for b in self.frames(q.epoch, q.lo, q.hi):
                query.reply(key, b)
                self.served += 1
        except (M.MessageError, OSError) as e:   # said to the asker; the source goes on
            self.errors += 1
            query.reply_err(str(e)[:200].encode())

    def before(self) -> tuple[int, float, int]:
        """What this source published in its earlier epochs (a restart resumes after it):
        (data messages, the highest watermark promised, the last earlier epoch or 0)."""
        from . import frames as F
        n, wm, last = 0, -1.0, 0
        for e in range(1, self.epoch):
            offs = self._offsets(e)
            if not offs:
                continue
            last = e
            data = self.path(e).read_bytes()
            for off in offs:
                (size,) = _LEN.unpack_from(data, off)
                try:
                    f = F.decode(data[off + 4:off + 4 + size], 1 << 26)
                except M.MessageError:
                    continue   # a frame we cannot read was never one a receiver took either
                n += len(f.msgs)
                wm = max(wm, f.wm)
        return n, wm, last

    def close(self) -> None:
        with self.lock:
            self.f.close()


def ask(session, key: str, epoch: int, lo: int, hi: int, timeout: float = 3.0) -> list[bytes]:
    """Frames lo..hi of `epoch` from the journal at `key` (as many as it holds and sends;
    errors and timeouts give fewer)."""
    out: list[bytes] = []
    want = lo
    while want <= hi:
        got = []
        for r in session.get(key, payload=msgspec.msgpack.encode(JournalQuery(epoch=epoch, lo=want, hi=hi)),
                             timeout=timeout, consolidation=zenoh.ConsolidationMode.NONE):   # every frame, one key
            if r.ok is not None:
                got.append(r.ok.payload.to_bytes())
        if not got:
            break
        out += got
        want += len(got)
    return out
