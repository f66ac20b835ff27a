"""Signatures that survive relays (security/sign.py): Ed25519 envelopes around orders,
reorganizations, mission confirmations, task delegations and commands, checked by the
receiver's `gate.Gate`; forged or replayed envelopes are refused with a reason and counted.
In process: no Zenoh session is opened."""
from __future__ import annotations

import json
import os
import stat
import time
import uuid

import msgspec
import pytest
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from hypothesis import given, settings
from hypothesis import strategies as st

from dissemination.keyspace import KeySpace
from saim_mesh.authority import commands as C
from saim_mesh.protocol import messages as M
from saim_mesh import scenario as S
from saim_mesh.protocol.gate import Gate
from saim_mesh.protocol import wire as W
from saim_mesh.security import SecurityError, make_pki, names_for
from saim_mesh.security import sign as G
from saim_mesh.launch.zenoh_config import config

from .conftest import SMALL

pytestmark = pytest.mark.timeout(120)
ROOT = "test/sign"
KS = KeySpace(ROOT)
ORDER = M.Order(10.0, "execute-plan", "p1", "A2")
ORDER_KEY = KS.key(ORDER, None, None)   # ord/A2


@pytest.fixture(scope="module")
def keys():
    return {n: Ed25519PrivateKey.generate() for n in ("hq", "console", "console.A", "ea.A2")}


def verifier(keys, require=True, window=G.WINDOW):
    """`hq` may sign orders: the mechanism's tests, whoever signs authority on a data key."""
    pubs = {n: k.public_key() for n, k in keys.items()}
    return G.Verifier(pubs, {**G.rules_for(pubs), "hq": ["ord/**"]}, ROOT, require=require, window=window)


def gate(keys, **kw):
    return Gate(5400.0, verifier=verifier(keys, **kw))


def signed_order(keys, n=1, who="hq", key=ORDER_KEY, msg=ORDER):
    return G.Signer(who, keys[who]).sign(key, M.encode(msg), n)


def wrap(fields: list) -> bytes:
    """An envelope made by hand: FIELDS in the ext an envelope travels in."""
    return msgspec.msgpack.encode(msgspec.msgpack.Ext(G.EXT, msgspec.msgpack.encode(fields)))


def unwrap(env: bytes) -> list:
    return msgspec.msgpack.decode(msgspec.msgpack.decode(env, type=msgspec.msgpack.Ext).data)


def rejected(g: Gate, payload: bytes, key: str) -> str:
    """The reason `g` refused `payload` (it must have)."""
    before = g.errors
    assert g.data(payload, key) is None
    assert g.errors == before + 1
    return g.rejects.recent[-1]


def test_round_trip(keys):
    g = gate(keys)
    env = signed_order(keys)
    assert G.is_signed(env) and not G.is_signed(M.encode(ORDER))
    assert g.data(env, ORDER_KEY) == ORDER and g.errors == 0
    # a command, signed by the console of A for a command from A to A2
    cmd = C.make("ack", alert="A2/1")
    key = KS.cmd("A2", "ack", "A")
    got = g.control(W.AckCmd, G.Signer("console.A", keys["console.A"]).sign(key, W.encode(cmd)), key, signed=True)
    assert got == cmd


def test_tampered_body_and_signature(keys):
    g = gate(keys)
    env = unwrap(signed_order(keys))
    forged = M.encode(M.Order(10.0, "abort-plan", "p1", "A2"))
    assert "bad signature" in rejected(g, wrap([*env[:4], forged, env[5]]), ORDER_KEY)
    sig = bytes([env[5][0] ^ 1]) + env[5][1:]
    assert "bad signature" in rejected(g, wrap([*env[:5], sig]), ORDER_KEY)
    assert g.rejects.by_kind == {"signed": 2}
    assert g.data(signed_order(keys), ORDER_KEY) == ORDER   # a forgery burnt no counter


def test_tampered_key(keys):
    g = gate(keys)
    env = unwrap(signed_order(keys))
    other = KS.key(M.Order(10.0, "execute-plan", "p1", "A1"), None, None)
    # the signed key changed: the signature no longer holds
    assert "bad signature" in rejected(g, wrap([*env[:3], other, *env[4:]]), other)
    # an intact envelope moved to another key
    assert "signed for" in rejected(g, signed_order(keys, n=2), other)
    # signed for ord/A1 with an order issued by A2 inside (what the key claims is checked)
    assert "differs from the key" in rejected(g, signed_order(keys, n=3, key=other), other)
    assert g.rejects.by_kind == {"signed": 3}


@pytest.mark.parametrize("bad", [f"{ROOT}/ord/*", f"{ROOT}/ord/**", f"{ROOT}//ord/A2", f"{ROOT}/ord/A2/",
                                 f"{ROOT}/ord/$*", "/", "**"])
def test_a_signed_key_that_is_no_concrete_key_is_refused(keys, bad):
    g = gate(keys)
    assert "not one concrete key" in rejected(g, signed_order(keys, key=bad), "store")
    assert "not one concrete key" in rejected(g, signed_order(keys, key=bad), bad)
    assert g.rejects.by_kind == {"signed": 2}


def test_unknown_signer_and_signer_not_allowed(keys):
    g = gate(keys)
    stranger = G.Signer("hq", Ed25519PrivateKey.generate())   # the right name, not the right key
    assert "bad signature" in rejected(g, stranger.sign(ORDER_KEY, M.encode(ORDER), 1), ORDER_KEY)
    nobody = G.Signer("ea.Z9", Ed25519PrivateKey.generate())
    assert "unknown signer 'ea.Z9'" in rejected(g, nobody.sign(ORDER_KEY, M.encode(ORDER), 1), ORDER_KEY)
    # an EA may not sign an order; a console may not sign a confirmation; console.A may
    # not sign a command sent as another unit's console
    assert "ea.A2 may not sign on 'ord'" in rejected(g, signed_order(keys, who="ea.A2"), ORDER_KEY)
    msn = M.MissionConfirm(5.0, "m1", "A2", "start")
    mkey = KS.key(msn, None, None)
    assert "console may not sign on 'msn'" in rejected(g, signed_order(keys, who="console", key=mkey, msg=msn), mkey)
    key = KS.cmd("A2", "ack", "BN")
    env = G.Signer("console.A", keys["console.A"]).sign(key, W.encode(C.make("ack", alert="A2/1")))
    assert g.control(W.AckCmd, env, key, signed=True) is None
    assert "console.A may not sign on 'cmd'" in g.rejects.recent[-1]
    assert g.rejects.by_kind == {"signed": 5}


def test_replayed_message_is_rejected_and_counted(keys):
    g = gate(keys, window=3)
    env = signed_order(keys, n=7)
    assert g.data(env, ORDER_KEY) == ORDER
    assert "replayed: counter 7 already taken from hq" in rejected(g, env, ORDER_KEY)
    for n in (9, 8, 10):
        assert g.data(signed_order(keys, n=n), ORDER_KEY) == ORDER
    # the window holds the last 3 (8, 9, 10): 7 fell out, and anything as old is refused
    assert "older than the last 3" in rejected(g, env, ORDER_KEY)
    assert "older than the last 3" in rejected(g, signed_order(keys, n=5), ORDER_KEY)
    assert g.rejects.by_kind == {"signed": 3}
    assert len(g.verifier.windows["hq"].seen) == 3
    # from the store (no key of its own): a repeat is taken, as a peer's re-fetch is
    assert g.data(signed_order(keys, n=10), "store") == ORDER
    # consoles count by time: two commands from one signer never share a counter
    s = G.Signer("console", keys["console"])
    assert s.next_n() < s.next_n() and abs(s.next_n() - time.time() * 1e6) < 60e6


@pytest.mark.parametrize("payload, why", [
    (wrap([1, "hq", 1, ORDER_KEY]), "Expected `array` of at least length 6"),
    (wrap([1, "hq", "1", ORDER_KEY, b"x", b"s" * 64]), "Expected `int`"),
    (wrap([2, "hq", 1, ORDER_KEY, b"x", b"s" * 64]), "Invalid enum value 2"),
    (wrap([1, "hq", 0, ORDER_KEY, b"x", b"s" * 64]), ">= 1"),
    (wrap([1, "../x", 1, ORDER_KEY, b"x", b"s" * 64]), "matching regex"),
    (wrap([1, "hq", 1, ORDER_KEY, b"x", b"s" * 63]), "length >= 64"),
    (wrap([1, "hq", 1, ORDER_KEY, b"x", b"s" * 64, "extra"]), "at most length 6"),
    (wrap([1, "hq", 1, "k" * 600, b"x", b"s" * 64]), "length <= 512"),
    (wrap([1, "hq", 1, ORDER_KEY, "text", b"s" * 64]), "Expected `bytes`"),
    (wrap([1, "hq", 1, ORDER_KEY, b"x", b"s" * 64])[:-3], "truncated"),
    (b"\xc7", "truncated"),
    (msgspec.msgpack.encode(msgspec.msgpack.Ext(7, b"x" * 80)), "ext type 7, not a signed envelope"),
    (msgspec.msgpack.encode(msgspec.msgpack.Ext(G.EXT, b"\x81\xa1v\x01")), "Expected `array`, got `object`"),
], ids=["short", "n-type", "version", "n-zero", "signer-name", "short-sig", "extra", "long-key", "body-type",
        "cut", "ext-head-only", "other-ext", "map-inside"])
def test_malformed_envelopes_are_counted_never_raised(keys, payload, why):
    g = gate(keys)
    assert why in rejected(g, payload, ORDER_KEY)
    assert g.rejects.by_kind == {"signed": 1}
    assert g.control(W.AckCmd, payload, KS.cmd("A2", "ack", "A"), signed=True) is None
    assert g.rejects.by_kind == {"signed": 2}


def test_oversize_and_truncated_real_envelopes(keys):
    g = gate(keys)
    env = signed_order(keys)
    for cut in (1, 10, len(env) // 2, len(env) - 1):
        assert "(envelope)" in rejected(g, env[:cut], ORDER_KEY)
    big = G.Signer("hq", keys["hq"]).sign(ORDER_KEY, b"\x80" * 70_000, 1)
    assert "over the 65536 limit" in rejected(g, big, ORDER_KEY)
    assert g.control(W.AckCmd, big, KS.cmd("A2", "ack", "A"), signed=True) is None
    with pytest.raises(ValueError, match="cannot sign"):
        G.Signer("hq", keys["hq"]).sign(ORDER_KEY, b"x" * (G.MAX_BODY + 1), 1)
    assert g.data(env, ORDER_KEY) == ORDER


def test_unsigned_authority_in_secure_and_open_mode(keys):
    secure, open_ = gate(keys), gate(keys, require=False)
    assert "an unsigned order message" in rejected(secure, M.encode(ORDER), ORDER_KEY)
    pos = M.LocationReport(1.0, "A2S1", 10.0, 50.0)
    assert secure.data(M.encode(pos), "x") == pos   # reports are not authority
    key = KS.cmd("A2", "ack", "A")
    assert secure.control(W.AckCmd, W.encode(C.make("ack", alert="A2/1")), key, signed=True) is None
    assert "unsigned command" in secure.rejects.recent[-1]
    # open mode: unsigned is taken, and an envelope is still checked when it comes
    assert open_.data(M.encode(ORDER), ORDER_KEY) == ORDER
    assert open_.data(signed_order(keys), ORDER_KEY) == ORDER
    assert "bad signature" in rejected(open_, G.Signer("hq", Ed25519PrivateKey.generate())
                                       .sign(ORDER_KEY, M.encode(ORDER), 2), ORDER_KEY)
    # no verifier at all: an envelope cannot be checked, so it is refused
    bare = Gate(5400.0)
    assert "no signers' keys" in rejected(bare, signed_order(keys), ORDER_KEY)
    assert bare.data(M.encode(ORDER), ORDER_KEY) == ORDER


# ---------------------------------------------------------------------------- files and the mesh

@pytest.fixture(scope="module")
def sc():
    return S.load(SMALL)


@pytest.fixture(scope="module")
def pki(tmp_path_factory, sc):
    d = tmp_path_factory.mktemp("pki")
    make_pki(d, names_for(sc, consoles=True))
    return d


def test_make_pki_writes_signing_keys_idempotently(tmp_path):
    make_pki(tmp_path, ["hq", "ea.A2"])
    key = tmp_path / "hq.sign.pem"
    assert stat.S_IMODE(os.stat(key).st_mode) == 0o600 and b"BEGIN PRIVATE KEY" in key.read_bytes()
    first = {p.name: p.read_bytes() for p in tmp_path.glob("*sign*")}
    signers = json.loads((tmp_path / "signers.json").read_text())
    assert set(signers["keys"]) == {"hq", "ea.A2"}
    make_pki(tmp_path, ["hq", "ea.A2"])
    assert {p.name: p.read_bytes() for p in tmp_path.glob("*sign*")} == first
    make_pki(tmp_path, ["hq", "ea.A2", "console"])
    assert set(json.loads((tmp_path / "signers.json").read_text())["keys"]) == {"hq", "ea.A2", "console"}
    assert (tmp_path / "hq.sign.pem").read_bytes() == first["hq.sign.pem"]
    # the public key in signers.json is the signing key's: a signature checks out
    v = G.load_verifier(tmp_path, ROOT)
    nk = KS.notice("A", "A2")   # ea.A2 signs its escalations
    assert v.open(G.load_signer(tmp_path, "ea.A2").sign(nk, b"x", 1), nk) == (nk, b"x")
    key.write_text("garbage")   # a damaged key is made again
    make_pki(tmp_path, ["hq"])
    assert key.read_bytes() != first["hq.sign.pem"]
    assert G.load_verifier(tmp_path, ROOT).keys["hq"].public_bytes_raw() != v.keys["hq"].public_bytes_raw()
    (tmp_path / "signers.json").write_text('{"v": 1, "keys": {"hq": "AAAA"}}')
    with pytest.raises(SecurityError, match="signers.json: bad signers file"):
        G.load_keys(tmp_path)


def test_secure_config_without_signing_keys_says_so(tmp_path, sc):
    make_pki(tmp_path, ["hq", "ea.A2"])
    (tmp_path / "ea.A2.sign.pem").unlink()
    conf = config(["tls/127.0.0.1:0"], None, pki=tmp_path, name="ea.A2", sc=sc, root=ROOT)
    with pytest.raises(SecurityError, match="ea.A2.sign.pem: file missing.*saim-mesh certs"):
        G.signer_for(conf)
    assert G.signer_for(config(["tcp/127.0.0.1:0"])) is None and G.verifier_for(config(), ROOT) is None


def test_a_peer_takes_signed_commands_only(pki, sc):
    """A live EA peer in secure mode: a command signed by the console of a unit above it is
    taken (and reaches the EA), an unsigned one is refused with its reason, one signed by a
    console whose key it is not is dropped, each counted."""
    from saim_mesh.live.peer import LivePeer
    root = f"test/{uuid.uuid4().hex[:8]}"
    ks = KeySpace(root)
    peer = LivePeer(sc, "A2", config(["tls/127.0.0.1:0"], None, pki=pki, name="ea.A2", sc=sc, root=root), root,
                    ["cp.A"], log=lambda *a, **k: None)
    got: list = []
    peer.out.result = got.append   # what it answers on cmdlog/A2
    cmd = C.make("ack", alert="A2/999")
    key = ks.cmd("A2", "ack", "A")
    peer.command(key, G.load_signer(pki, "console.A").sign(key, W.encode(cmd)))
    assert got[-1].req == cmd.req and "unknown alert" in got[-1].error   # through the gate, to the EA
    peer.command(key, W.encode(cmd))
    assert not got[-1].ok and "unsigned command" in got[-1].error
    n = len(got)
    peer.command(key, G.load_signer(pki, "console.B").sign(key, W.encode(cmd)))   # not B's key
    assert len(got) == n
    assert peer.gate.rejects.by_kind == {"ackcmd": 1, "signed": 1}
    assert "console.B may not sign" in peer.gate.rejects.recent[-1]


@settings(max_examples=300, deadline=None)
@given(head=st.sampled_from([0xC7, 0xC8, 0xC9, 0xD4, 0xD8]), rest=st.binary(max_size=400))
def test_arbitrary_envelope_bytes_are_counted_never_raised(keys, head, rest):
    g = gate(keys)
    assert g.data(bytes([head]) + rest, ORDER_KEY) is None
    assert g.control(W.AckCmd, bytes([head]) + rest, KS.cmd("A2", "ack", "A"), signed=True) is None
    assert g.errors == 2 and g.rejects.by_kind == {"signed": 2}


@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_a_real_envelope_with_any_byte_changed_is_refused(keys, data):
    env = bytearray(signed_order(keys))
    i = data.draw(st.integers(0, len(env) - 1))
    env[i] ^= data.draw(st.integers(1, 255))
    g = gate(keys)
    assert g.data(bytes(env), ORDER_KEY) is None and g.errors == 1


# ---------------------------------------------------------------------------- end to end

def test_an_escalation_is_signed_by_its_owners_ea_only(keys):
    """An EA signs the notices of its own alerts (notice/<superior>/<owner>): the superior
    takes A2's escalation signed by ea.A2, and refuses it signed by anyone else, on another
    owner's key, or unsigned in secure mode."""
    n = W.make(W.Notice, kind="escalate", t=1242.0, owner="A2", alert="A2/1", story="A2/1", type="out-of-position",
               priority="immediate", subjects=["A2"], message="off route", count=1, to="A", due_t=942.0)
    key = KS.notice("A", "A2")
    g = gate(keys)
    assert g.control(W.Notice, G.Signer("ea.A2", keys["ea.A2"]).sign(key, W.encode(n)), key, signed=True) == n
    for who, k in (("console.A", key), ("hq", key), ("ea.A2", KS.notice("A", "B1"))):
        before = g.errors
        assert g.control(W.Notice, G.Signer(who, keys[who]).sign(k, W.encode(n)), k, signed=True) is None
        assert g.errors == before + 1 and "may not sign" in g.rejects.recent[-1], (who, k)
    before = g.errors
    assert g.control(W.Notice, W.encode(n), key, signed=True) is None and g.errors == before + 1
