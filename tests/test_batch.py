"""Batches, coarse subscriptions and the exact filter, without processes: what the
replay sends per group and tick, what a peer subscribes to and keeps."""
from __future__ import annotations

import msgspec
import pytest
import zenoh

from dissemination.coarse import coarse, overlapping
from dissemination.exact import exact
from dissemination.interest import Interest
from dissemination.keyspace import KeySpace
from saim_mesh import batch as B
from saim_mesh import messages as M
from saim_mesh import gate as G
from saim_mesh import wire as W
from saim_mesh.runner import config_for, make_ea

ROOT = "saim/t"


class FakePub:
    def __init__(self, key, sent):
        self.key, self.sent = key, sent

    def put(self, payload, **_):
        self.sent.append((self.key, payload))


class FakeSession:
    def __init__(self):
        self.sent: list[tuple[str, bytes]] = []

    def declare_publisher(self, key, **_):
        return FakePub(key, self.sent)


def pos(entity: str, path: str, t: float = 1.0, block: str = "X1Y1", cell: str = "x4y4"):
    m = M.LocationReport(t, entity, 1.0, 2.0)
    return f"{ROOT}/pos/{block}/{cell}/{path}/{entity}", M.encode(m)


def test_batcher_groups_a_ticks_reports_and_leaves_authority_messages_single():
    s = FakeSession()
    b = B.Batcher(s, B.groups_of(ROOT))
    k1, p1 = pos("e1", "BN/A/A1")
    k2, p2 = pos("e2", "BN/A/A2")
    k3, p3 = pos("e3", "BN/B")
    assert b.add(k1, 1, p1) and b.add(k2, 3, p2) and b.add(k3, 4, p3)
    assert not b.add(f"{ROOT}/ord/BN", 2, M.encode(M.Order(1.0, "abort-plan", "p", "BN")))
    assert not b.add(f"{ROOT}/hit/g1/s1", 5, M.encode(M.SensorHit(1.0, "s1", 1.0, 2.0)))
    assert s.sent == []   # nothing before the flush (the tick)
    b.flush()
    got = {k: msgspec.msgpack.decode(p, type=B.Batch).entries for k, p in s.sent}
    assert got == {f"{ROOT}/pos/X1Y1/_b/BN/A": [(1, k1, p1), (3, k2, p2)], f"{ROOT}/pos/X1Y1/_b/BN/B": [(4, k3, p3)]}
    assert (b.sent, b.entries) == (2, 3)


def test_batcher_splits_at_the_payload_bound():
    s = FakeSession()
    b = B.Batcher(s, B.groups_of(ROOT), max_bytes=2000)
    for i in range(100):
        key, payload = pos(f"e{i:03d}", "BN/A")
        b.add(key, i + 1, payload)
    b.flush()
    assert len(s.sent) > 1 and all(len(p) <= 2000 for _, p in s.sent)
    seqs = [q for _, p in s.sent for q, _, _ in msgspec.msgpack.decode(p, type=B.Batch).entries]
    assert seqs == list(range(1, 101))


def _batch(entries) -> bytes:
    return W.encode(B.Batch(v=W.VERSION, entries=entries))


@pytest.mark.parametrize("payload, field", [
    (b"\xc1junk", "(message)"),
    (msgspec.msgpack.encode({"v": 1, "entries": []}), "(message)"),          # empty
    (msgspec.msgpack.encode({"v": 2, "entries": [[1, "k", b"x"]]}), "(message)"),   # version
    (msgspec.msgpack.encode({"v": 1, "entries": [[-1, "k", b"x"]]}), "(message)"),  # negative seq
    (msgspec.msgpack.encode({"v": 1, "entries": [[1, "k", "text"]]}), "(message)"),  # payload not bytes
    (_batch([(5, pos("e1", "BN/A")[0], b"x"), (4, pos("e2", "BN/A")[0], b"y")]), "entries"),   # out of order
    (b"\x90" * 70000, "(bytes)"),
])
def test_bad_batches_are_rejected_whole_and_counted(payload, field):
    gate = G.Gate(3600.0)
    assert B.unpack(gate, B.groups_of(ROOT), payload, f"{ROOT}/pos/X1Y1/_b/BN/A") == []
    assert gate.rejects.total == 1 and f"field '{field}'" in gate.rejects.recent[-1]


def test_an_entry_on_another_groups_key_is_left_out_and_counted():
    gate = G.Gate(3600.0)
    k1, p1 = pos("e1", "BN/A/A1")
    k2, p2 = pos("e2", "BN/B")            # not of group BN/A
    k3, p3 = pos("e3", "BN/A", block="X2Y2")   # another block
    got = B.unpack(gate, B.groups_of(ROOT), _batch([(1, k1, p1), (2, k2, p2), (3, k3, p3)]),
                   f"{ROOT}/pos/X1Y1/_b/BN/A")
    assert got == [(1, k1, p1)] and gate.rejects.total == 2


@pytest.fixture(scope="module")
def interests(small):
    ks = KeySpace.of(small, ROOT)
    to = small.taskorg
    paths = [to.path(u) for u in to.units]
    out = {}
    for unit in ("BN", "A", "A2", "B1"):
        cfg = config_for(small, unit)
        ea = make_ea(small, unit, cfg)
        ea.start(0.0)
        fine = Interest(ks, cfg["dissemination"]["radius_m"], int(cfg["dissemination"]["block_share"])).keys(
            ea.domain) - {ks.clock()}
        out[unit] = fine, coarse(fine, ROOT, B.groups_of(ROOT), paths)
    return out


def test_coarse_subscriptions_are_fewer_never_overlap_and_cover_the_fine_interest(small, interests):
    """No sample is delivered twice, and every key the EA needs reaches it (on its
    group's batch key for batched families, on its own key otherwise)."""
    ks, groups = KeySpace.of(small, ROOT), B.groups_of(ROOT)
    keys = sorted({ks.key(ev, small.taskorg, small.projection) for ev in small.events})
    for unit, (fine, zsubs) in interests.items():
        assert overlapping(zsubs) == [], unit
        assert len(zsubs) <= len(fine), unit
        fine_k, z_k = [zenoh.KeyExpr(e) for e in fine], [zenoh.KeyExpr(e) for e in zsubs]
        for k in keys:
            if any(f.intersects(zenoh.KeyExpr(k)) for f in fine_k):
                on = zenoh.KeyExpr(groups.group(k) or k)
                assert sum(z.intersects(on) for z in z_k) == 1, (unit, k)
    assert len(interests["BN"][1]) < len(interests["BN"][0]) / 3


def test_exact_filter_agrees_with_zenoh_matching(small, interests):
    ks = KeySpace.of(small, ROOT)
    keys = sorted({ks.key(ev, small.taskorg, small.projection) for ev in small.events})
    keys += [f"{ROOT}/ord/BN/extra", f"{ROOT}/pos/X1Y1", "other/root/pos/a/b/BN/e", f"{ROOT}/msn/A2/m"]
    for unit, (fine, _) in interests.items():
        want = exact(fine, ROOT)
        fine_k = [zenoh.KeyExpr(e) for e in fine]
        for k in keys:
            assert want(k) == any(f.intersects(zenoh.KeyExpr(k)) for f in fine_k), (unit, k)


def test_exact_filter_on_odd_expressions_agrees_with_zenoh():
    exprs = {f"{ROOT}/a/**/z", f"{ROOT}/b/x$*y/*", f"{ROOT}/c/*", f"{ROOT}/d/k", "other/**/q", f"{ROOT}/e/**"}
    keys = [f"{ROOT}/a/z", f"{ROOT}/a/1/2/z", f"{ROOT}/a/1/2", f"{ROOT}/b/xAy/1", f"{ROOT}/b/xy/1", f"{ROOT}/b/xA/1",
            f"{ROOT}/c/1", f"{ROOT}/c/1/2", f"{ROOT}/d/k", f"{ROOT}/d/k/1", "other/q", "other/1/q", "other/1",
            f"{ROOT}/e", f"{ROOT}/e/1/2", f"{ROOT}/f/1"]
    want = exact(exprs, ROOT)
    for k in keys:
        assert want(k) == any(zenoh.KeyExpr(e).intersects(zenoh.KeyExpr(k)) for e in exprs), k


def test_store_log_answers_like_the_list_it_replaces():
    from saim_mesh.store import KeyIndex, Log
    log, ref = Log(), []
    for i in range(1, 2001):
        e = (i, bytes([i % 251]) * (i % 97))
        log.append(e)
        ref.append(e)
    assert len(log) == 2000 and log[0] == ref[0] and log[-1] == ref[-1] and log[1234] == ref[1234]
    assert log[0:] == ref and log[1500:] == ref[1500:] and log[2000:] == [] and log[10:20] == ref[10:20]
    with pytest.raises(ValueError):
        log.append((5, b"x"))     # seqs follow each other: the store's seq is its position
    idx = KeyIndex()
    for n, k in enumerate(["a", "b", "a"], 1):
        idx.setdefault(k, []).append(n)
    assert list(idx["a"]) == [1, 3] and idx.nbytes == 12 and log.nbytes == 16000
