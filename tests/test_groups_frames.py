"""A source's flushes by key group and an EA's assembly of them (saim_mesh/live/groupframes):
whatever order the progress and group frames arrive in, the EA's flush k is the source's
flush k less the groups it does not hear, in the flush's own order; it never waits for a
group it does not hear; a heard group's frame that does not come is a gap it sees, filled
from the journal's whole flush."""
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from saim_mesh.protocol import messages as M
from saim_mesh.live import frames as F
from saim_mesh.live import groupframes as G

GROUPS = ["pos/X1Y1/BN/A", "pos/X1Y1/BN/B", "pos/X2Y1/BN/A", "trk/X1Y1", "msn/A1", "ord/BN"]


def flushes(draw):
    n = draw(st.integers(1, 6))
    out, k = [], 0
    for seq in range(1, n + 1):
        m = draw(st.integers(0, 8))
        msgs = [M.encode(M.LocationReport(float(seq) + i / 100, f"E{k + i}", 1.0, 2.0)) for i in range(m)]
        k += m
        out.append((seq, float(seq), msgs, draw(st.lists(st.sampled_from(GROUPS), min_size=m, max_size=m))))
    return out


@settings(max_examples=200, deadline=None)
@given(data=st.data())
def test_assembled_flushes_are_the_sources_less_what_is_not_heard(data):
    fl = flushes(data.draw)
    heard = set(data.draw(st.lists(st.sampled_from(GROUPS), unique=True)))
    counters: dict[str, int] = {}
    wire, wholes = [], {}
    for seq, wm, msgs, groups in fl:
        gfs, prog, whole = G.split("cp.A", 1, seq, wm, msgs, groups, counters)
        wholes[seq] = whole
        wire += [("g", G.encode(gf)) for gf in gfs if gf.group in heard] + [("p", G.encode(prog))]
    wire = data.draw(st.permutations(wire))
    asm = G.Assembler(lambda g: g in heard)
    progress = {}
    for kind, b in wire:
        if kind == "g":
            asm.group(G.decode_group(b, 1 << 20))
        else:
            p = G.decode_progress(b, 1 << 20)
            progress[p.seq] = p
    got = []
    for seq in sorted(progress):   # the progress stream in its sequence
        f = asm.ready(progress[seq])
        assert f is not None, f"flush {seq} waits for {asm.missing(progress[seq])}"
        got.append(f)
    for f in got:
        w = wholes[f.seq]
        want = [b for b, g in zip(w.msgs, w.groups) if g in heard]
        assert f.msgs == want and f.wm == w.wm and all(g in heard for g in f.groups)
        # the journal's whole flush, filled through the assembler, is the same flush
        assert G.Assembler(lambda g: g in heard).fill(F.decode(F.encode(w), 1 << 20)).msgs == want
    assert not asm.groups   # nothing left behind


def test_a_missing_heard_group_is_a_gap_an_unheard_one_is_not():
    counters: dict[str, int] = {}
    msgs = [M.encode(M.LocationReport(1.0, "E1", 1.0, 2.0)), M.encode(M.LocationReport(1.0, "E2", 1.0, 2.0))]
    gfs, prog, _ = G.split("cp.A", 1, 1, 0.0, msgs, ["msn/A1", "ord/BN"], counters)
    asm = G.Assembler(lambda g: g == "msn/A1")
    assert asm.missing(prog) == ["msn/A1"] and asm.ready(prog) is None
    asm.group(gfs[1])   # a group it does not hear: kept out
    assert asm.ready(prog) is None
    asm.group(gfs[0])
    f = asm.ready(prog)
    assert f.msgs == [msgs[0]] and f.groups == ["msn/A1"]
    assert counters == {"msn/A1": 1, "ord/BN": 1}
    gfs2, prog2, _ = G.split("cp.A", 1, 2, 2.0, [msgs[0]], ["ord/BN"], counters)
    assert prog2.last == {"ord/BN": 2} and asm.ready(prog2).msgs == []   # nothing heard in it: no wait


def test_bad_group_frames_are_refused_with_a_reason():
    gf = G.GroupFrame(v=1, source="cp.A", epoch=1, group="ord/BN", seq=1, at=1, idx=[0, 1], msgs=[b"x"])
    with pytest.raises(M.MessageError, match="idx"):
        G.decode_group(G.encode(gf), 1 << 20)
    with pytest.raises(M.MessageError, match="limit"):
        G.decode_progress(b"x" * 100, 10)
    with pytest.raises(M.MessageError):
        G.decode_group(b"\x00junk", 1 << 20)


LON = st.floats(-180, 180, allow_nan=False)
LAT = st.floats(-90, 90, allow_nan=False)
NAME = st.text(min_size=1, max_size=40)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 1e6, allow_nan=False) | st.integers(0, 10**8).map(lambda q: q / 100), NAME,
                          LON | st.integers(-1_800_000_000, 1_800_000_000).map(lambda q: q / 1e7),
                          LAT | st.integers(-900_000_000, 900_000_000).map(lambda q: q / 1e7)), max_size=20))
def test_a_group_frame_gives_back_every_message_byte_for_byte(rows):
    """Positions packed as arrays or not, the EA gets the bytes the source encoded: lossless."""
    msgs = [M.encode(M.LocationReport(t, e, lon, lat)) for t, e, lon, lat in rows]
    msgs.append(M.encode(M.Order(t=1.0, action="abort-plan", plan="p1", issuer="BN")))
    gf = G.GroupFrame(v=1, source="cp.A", epoch=1, group="pos/X1Y1/BN/A", seq=1, at=1,
                      idx=list(range(len(msgs))), msgs=msgs)
    back = G.decode_group(G.encode(gf), 1 << 20)
    assert back == gf
    assert [M.decode(b) for b in back.msgs] == [M.decode(b) for b in msgs]


def test_a_recorded_position_travels_in_a_third_of_its_bytes():
    b = M.encode(M.LocationReport(1234.56, "2C2S2E04", -116.3680719, 35.2191442))
    one = G.GroupFrame(v=1, source="cp.A", epoch=1, group="pos/X1Y1/BN/A", seq=1, at=1, idx=[0], msgs=[b])
    two = G.GroupFrame(v=1, source="cp.A", epoch=1, group="pos/X1Y1/BN/A", seq=1, at=1, idx=[0, 1], msgs=[b, b])
    assert len(G.encode(two)) - len(G.encode(one)) <= len(b) / 2.5
    odd = M.encode(M.LocationReport(1 / 3, "E1", 1.0, 2.0))   # a time off the 1/100 s grid: sent as it is
    three = G.GroupFrame(v=1, source="cp.A", epoch=1, group="pos/X1Y1/BN/A", seq=1, at=1, idx=[0, 1], msgs=[b, odd])
    assert len(G.encode(three)) - len(G.encode(one)) > len(odd)


def test_a_bad_packed_position_is_refused_with_a_reason():
    import msgspec
    wire = msgspec.msgpack.encode([1, "cp.A", 1, "pos/X", 1, 1, [0], [[5, "é" * 20, 1, 2]]])
    with pytest.raises(M.MessageError, match="entity of 40 bytes"):
        G.decode_group(wire, 1 << 20)
    wire = msgspec.msgpack.encode([1, "cp.A", 1, "pos/X", 1, 1, [0], [[5, "E1", 2_000_000_000, 2]]])
    with pytest.raises(M.MessageError, match="decode"):
        G.decode_group(wire, 1 << 20)
