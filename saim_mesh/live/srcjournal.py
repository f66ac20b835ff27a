"""A source's durable journal (issue 31.1): every frame it published, per epoch, in an
append-only file beside its epoch counter, served by a queryable on `srcj/<name>` for
catch-up beyond the advanced publisher's in-memory cache (a late joiner after a long
run, an EA that missed more than the cache holds, frames of an epoch before the source
restarted: the cache dies with the process, the file does not).

A query is a `JournalQuery` (epoch, first and last seq wanted, at most how many bytes);
the answer is `HELD` (a few bytes, never yielding: the asker knows the journal was
reached), then one reply per frame held, in order, at most `MAX_FRAMES` and the bytes
asked for per query (ask again from where it stopped), or "none held". Over a slow radio
link the frames can yield to live traffic (`reply_qos`: DROP at a lower priority) and be
paced (`Pacer`: at most so many bytes a second over every asker together, so that k EAs
catching up across one link leave room for the live frames behind them); the
`Asker` then takes what came in sequence, asks again from the first one missing, and
sizes its asks to what came back in time (AIMD): an answer of `HELD` alone (every frame
dropped) is congestion, not a journal that is not there. A query that cannot be read is answered
with an error, and the source lives on. Files: `<dir>/<name>.<epoch>.frames`, records length-prefixed (4 bytes,
big-endian); a half-written last record (a kill) is ignored on reading."""
from __future__ import annotations

import struct
import threading
import time
from pathlib import Path
from typing import Annotated

import msgspec
import zenoh

from ..protocol import messages as M
from ..protocol import wire as W

_LEN = struct.Struct(">I")
MAX_FRAMES = 2_000
MAX_BYTES = 16 * 2**20
FIRST_ASK_BYTES = 16 * 1024   # an asker's first chunk (2 s at 64 kbit/s): doubled while it comes in time, halved when not
MIN_ASK_BYTES = 4 * 1024
ASK_TIMEOUT_S = 3.0      # an ask's wait for its replies, doubled (to `MAX_ASK_TIMEOUT_S`) while they come late
MAX_ASK_TIMEOUT_S = 12.0
NONE_HELD = b"none held"
HELD = b"\x00held"   # not a frame (a frame is a msgpack map): the journal was reached
PACED = b"\x00paced"   # ... and held more than it sent now (`Pacer`): ask again later, not at once
YIELDING = {"congestion_control": zenoh.CongestionControl.DROP, "priority": zenoh.Priority.DATA_LOW}


CATCH_UP_KBIT = 24.0   # a yielding journal's pace: under half of a 64 kbit/s radio, the rest for live frames


class Pacer:
    """A token bucket over a journal's answers: `rate` bytes a second, `burst` at once.
    A lower Zenoh priority does not keep live frames on time once the catch-up's bytes are
    in the connection (bench/results/radio_priority.json: 11.6 s behind a yielding bulk,
    under 1 s behind one paced below the link's rate), so the journal sends less rather
    than lower. An ask beyond the bucket gets the frames it can pay for (at least one while
    the bucket is not in debt, and at most `burst` bytes, so that the askers share it); the
    journal says `PACED` and the asker comes back later for the rest. `clock`: monotonic
    seconds (a test's own)."""

    def __init__(self, rate: float, burst: float | None = None, clock=time.monotonic):
        if not rate > 0:
            raise ValueError(f"catch-up pace {rate!r} bytes/s: must be > 0")
        self.rate, self.burst, self.clock = rate, burst if burst is not None else rate, clock
        self.tokens, self.at = self.burst, clock()
        self.withheld = 0   # frames asked for and not sent at once (asked again)

    def grant(self, sizes: list[int]) -> int:
        """How many of these frames (in order) go now; their bytes are taken from the bucket."""
        now = self.clock()
        self.tokens = min(self.burst, self.tokens + (now - self.at) * self.rate)
        self.at = now
        n = given = 0
        while n < len(sizes) and self.tokens > 0 and given < self.burst:
            self.tokens -= sizes[n]
            given += sizes[n]
            n += 1
        self.withheld += len(sizes) - n
        return n


class JournalQuery(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """Frames `lo`..`hi` (inclusive) of `epoch` of the queried source, at most `max_bytes`
    of them (at least the first)."""
    epoch: W.Seq
    lo: W.Seq
    hi: W.Seq
    max_bytes: Annotated[int, msgspec.Meta(ge=1, le=MAX_BYTES)] = MAX_BYTES


class SourceJournal:
    """Append-only frames of one source, indexed by (epoch, seq); thread-safe: the source
    appends, the queryable's callback reads."""

    def __init__(self, state_dir: str | Path, name: str, epoch: int, reply_qos: dict | None = None,
                 pacer: Pacer | None = None):
        self.dir, self.name, self.epoch = Path(state_dir), name, epoch
        self.reply_qos = reply_qos or {}   # YIELDING across radio links
        self.pacer = pacer                 # ... and paced there
        self.dir.mkdir(parents=True, exist_ok=True)
        self.lock = threading.Lock()
        self.f = open(self.path(epoch), "ab")
        self.index: dict[int, list[int]] = {epoch: []}   # epoch -> offset of seq 1, 2, ...
        self.served = 0
        self.errors = 0
        self.asked_at: float | None = None   # monotonic: when it was last asked (a source lingers while asked)

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

    def frames(self, epoch: int, lo: int, hi: int, max_bytes: int = MAX_BYTES) -> list[bytes]:
        """Frames lo..hi of `epoch` held here (fewer at the bounds, past what is held or past
        `max_bytes`, but always the first one held)."""
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
                    if len(b) != n or out and size + n > max_bytes:
                        break
                    out.append(b)
                    size += n
            return out

    def serve(self, query, key: str) -> None:
        """Answer one query (a Zenoh queryable's callback): the frames, or an error."""
        self.asked_at = time.monotonic()
        try:
            raw = query.payload.to_bytes() if query.payload is not None else b""
            if len(raw) > 256:
                raise M.MessageError("journalquery", "(bytes)", f"{len(raw)} bytes, over 256")
            try:
                q = msgspec.msgpack.decode(raw, type=JournalQuery)
            except (msgspec.ValidationError, msgspec.DecodeError) as e:
                raise M.MessageError("journalquery", "(decode)", str(e)[:160]) from None
            frames = self.frames(q.epoch, q.lo, q.hi, q.max_bytes)
            held = len(frames)
            if self.pacer is not None:
                with self.lock:   # answers come on Zenoh's threads
                    frames = frames[:self.pacer.grant([len(b) for b in frames])]
            if not held:   # said, so that the asker stops asking (an answer that never came is no such word)
                query.reply_err(NONE_HELD)
            else:   # reached, whatever becomes of the yielding frames on the way
                query.reply(key, HELD, congestion_control=zenoh.CongestionControl.BLOCK)
            for b in frames:
                query.reply(key, b, **self.reply_qos)
                self.served += 1
            if len(frames) < held:   # the rest later: the asker does not ask again at once
                query.reply(key, PACED, congestion_control=zenoh.CongestionControl.BLOCK)
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


class Asker:
    """Asks one source's journal for frames, in sequence, the way TCP sends: each ask at most
    `chunk` bytes, doubled when the answer came whole and in time, halved when it did not
    (a congested link drops yielding replies, or the timeout cut them), so that k askers
    behind one slow link share it instead of each flooding it. And like TCP's retransmission
    timer, an ask the journal answered (`HELD`) but whose frames did not come in time waits
    twice as long next time, up to `MAX_ASK_TIMEOUT_S`: a router queue of a few full batches
    drains in seconds over what a slow radio link has spare, longer than a fixed timeout
    would wait, and then every reply would come after its asker stopped listening."""

    def __init__(self, timeout: float = ASK_TIMEOUT_S, chunk: int = FIRST_ASK_BYTES):
        self.base = self.timeout = timeout
        self.chunk = chunk
        self.why = ""   # why the last ask ended: done, none held, no answer, congested

    def ask(self, session, key: str, epoch: int, lo: int, hi: int, read, budget_s: float = 3.0) -> list[tuple]:
        """Frames lo..hi of `epoch` from the journal at `key`, in sequence from `lo` as far
        as they came within `budget_s` of wall time (no new ask after it; the last may wait
        out its own timeout), each as (bytes, `read(bytes)`): the
        frame read once, with its `seq` (None: it cannot be read). Fewer when the journal
        holds fewer (`why` "none held"), nobody answers ("no answer"), or the link gave no
        more in time ("congested": also when only `HELD` came, every frame dropped on the way)."""
        out: list[tuple] = []
        want, silent = lo, 0
        self.why = "done"
        end = time.monotonic() + budget_s
        while want <= hi:
            if time.monotonic() >= end:
                self.why = "congested"
                break
            got: dict[int, tuple] = {}
            said_none = answered = paced = False
            sent = time.monotonic()
            q = msgspec.msgpack.encode(JournalQuery(epoch=epoch, lo=want, hi=hi, max_bytes=self.chunk))
            for r in session.get(key, payload=q, timeout=self.timeout,
                                 consolidation=zenoh.ConsolidationMode.NONE):   # every frame, one key
                answered = True
                if r.ok is not None:
                    b = r.ok.payload.to_bytes()
                    if b == HELD:   # the journal was reached (answered): nothing to read
                        continue
                    if b == PACED:
                        paced = True
                        continue
                    f = read(b)
                    if f is not None and want <= f.seq <= hi:
                        got.setdefault(f.seq, (b, f))
                elif r.err is not None and r.err.payload.to_bytes() == NONE_HELD:
                    said_none = True
            late = time.monotonic() - sent > 0.8 * self.timeout
            start = want
            while want in got:
                out.append(got.pop(want))
                want += 1
            if said_none:
                self.why = "none held"
                break
            if paced:   # the journal's pace, shared by every asker: no faster by asking again now
                self.why = "paced"
                break
            if want == start and not answered and not late:   # no journal there (or no link): a few tries
                silent += 1
                if silent >= 3:
                    self.why = "no answer"
                    break
            whole = want > start and not got and not late   # something came, no hole, in time
            self.chunk = min(MAX_BYTES, self.chunk * 2) if whole else max(MIN_ASK_BYTES, self.chunk // 2)
            if answered and (late or want == start):   # reached, but its frames did not come in time
                self.timeout = min(MAX_ASK_TIMEOUT_S, self.timeout * 2)
            elif whole:
                self.timeout = max(self.base, self.timeout / 2)
        return out

