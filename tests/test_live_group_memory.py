"""Group frames kept for assembly count against an EA peer's memory bound (`[mesh]
max_held_mb`, shared with the frames its sequencer holds): what the bound has no room for is
dropped and counted, its flush then comes whole from the source's journal, and the bytes of
what was assembled are given back. Pure: no mesh."""
from __future__ import annotations

from dissemination.keyspace import KeySpace
from saim_mesh.live import bygroup as BG
from saim_mesh.live import groupframes as GF
from saim_mesh.protocol import gate as G

KS = KeySpace("t")


def flush(seq: int, group_seq: dict, groups=("a", "b", "c")):
    msgs = [f"m{seq}-{g}".encode() * 20 for g in groups]
    return GF.split("s", 1, seq, float(seq), msgs, list(groups), group_seq)


def intake(limit: int, journal=None) -> BG.GroupIntake:
    gi = BG.GroupIntake(KS, 1 << 20, G.Gate(1e9, 1 << 20), print, journal=journal)
    gi.room = lambda n: gi.bytes + n <= limit
    return gi


def arrive(gi: BG.GroupIntake, x) -> object:
    rest = GF.PROGRESS if type(x) is GF.Progress else x.group
    return gi.arrive(GF.encode(x), f"{KS.src('s')}/{rest}", "s", rest)


def test_group_frames_held_are_counted_and_given_back_when_assembled():
    gi, gs = intake(1 << 20), {}
    gfs, prog, _ = flush(1, gs)
    for gf in gfs:
        assert arrive(gi, gf) is None
    assert gi.bytes == sum(len(GF.encode(gf)) for gf in gfs)
    p = arrive(gi, prog)
    f = gi.assemble(p)
    assert f is not None and len(f.msgs) == 3
    assert gi.bytes == 0 and gi.dropped == 0


def test_a_group_frame_beyond_the_bound_is_dropped_and_its_flush_comes_from_the_journal(monkeypatch):
    gs = {}
    gfs, prog, whole = flush(1, gs)
    asked = []

    def journal(source, epoch, lo, hi):
        asked.append((source, epoch, lo, hi))
        yield b"", "", whole
    one = len(GF.encode(gfs[0]))
    gi = intake(one + one // 2, journal)   # room for one group frame, not two
    for gf in gfs:
        arrive(gi, gf)
    assert gi.dropped == 2 and gi.bytes == one
    p = arrive(gi, prog)
    assert gi.assemble(p) is None   # two heard groups missing: it waits for them first
    clock = [BG.time.monotonic() + BG.GAP_WAIT_S + 1]
    monkeypatch.setattr(BG.time, "monotonic", lambda: clock[0])
    f = gi.assemble(p)
    assert asked == [("s", 1, 1, 1)] and f is not None
    assert f.msgs == whole.msgs and gi.gaps == 0 and gi.filled == 1
    assert gi.bytes == 0


def test_a_flush_taken_whole_from_the_journal_gives_its_group_frames_bytes_back():
    gi, gs = intake(1 << 20), {}
    gfs, _, whole = flush(1, gs)
    for gf in gfs[:2]:
        arrive(gi, gf)
    assert gi.bytes > 0
    assert gi.heard_only(whole).msgs == whole.msgs
    assert gi.bytes == 0
