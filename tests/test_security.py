"""Identities (mTLS certificates) and access-control rules generated from the scenario:
the PKI, the generated rules, and real Zenoh sessions (one process, one session each,
loopback, free ports) showing forged orders, frames, tokens and journal queries dropped.
Synchronisation is on queues, matching listeners and link events, never on sleeps."""
from __future__ import annotations

import json
import os
import stat
import string
import time
import uuid

import pytest
import zenoh
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID
from hypothesis import given, settings
from hypothesis import strategies as st

from saim_mesh import scenario as S
from saim_mesh.scenario import mesh_units
from saim_mesh.security import (SecurityError, access_control, check_files, check_identity, endpoint_tls,
                                make_pki, names_for, secure_config, tls_config)
from saim_mesh.launch.zenoh_config import config, free_port

from .conftest import ROOT, SMALL
from .zqueue import CallbackQueue

pytestmark = pytest.mark.timeout(120)
SENSORS = ROOT / "scenarios" / "small-sensors"
WAIT = 10.0   # upper bound of every wait on loopback


@pytest.fixture(scope="module")
def small_sc():
    return S.load(SMALL, events=False)


@pytest.fixture(scope="module")
def pki(tmp_path_factory, small_sc):
    d = tmp_path_factory.mktemp("pki")
    return d, make_pki(d, names_for(small_sc))


def cert(p):
    return x509.load_pem_x509_certificate(p.read_bytes())


def spki(pub):
    return pub.public_bytes(serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo)


# ---------------------------------------------------------------------------- PKI

def test_names_for_scenario(small_sc):
    names = names_for(small_sc)
    plain = [n for n in names if not n.startswith("source.")]
    assert plain[-3:] == ["observer", "console", "tak"] and "replay" not in names
    assert [n[3:] for n in names if n.startswith("ea.")] == mesh_units(small_sc)
    # a live source per command post: every mesh unit and every unit with subordinates
    to = small_sc.taskorg
    cps = set(mesh_units(small_sc)) | {p for p in to.parent.values() if p} | {u for u, p in to.parent.items()
                                                                              if p == to.root}
    assert sorted(n[len("source.cp."):] for n in names if n.startswith("source.")) == sorted(cps)
    two = names_for(small_sc, ["A2", "C"])
    assert [n for n in two if not n.startswith("source.")] == ["ea.A2", "ea.C", "observer", "console", "tak"]
    fused = names_for(S.load(SENSORS, events=False), ["BN"])
    assert [n for n in fused if not n.startswith("source.")] == ["ea.BN", "observer", "console", "tak"]
    assert {"source.fusion.F", "source.fusion.N"} <= set(fused)   # a fusion node is a live source of tracks
    with pytest.raises(SecurityError, match="ZZ"):
        names_for(small_sc, ["ZZ"])


def test_certificates_verify_against_the_ca(pki, small_sc):
    d, made = pki
    ca = cert(d / "ca.pem")
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    ca.verify_directly_issued_by(ca)   # self-signed
    assert set(made) == set(names_for(small_sc))
    for name, (pem, key) in made.items():
        assert pem == d / f"{name}.pem" and key == d / f"{name}.key" and pem.is_absolute()
        c = cert(pem)
        c.verify_directly_issued_by(ca)   # raises on a bad signature
        assert c.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == name
        assert not c.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
        san = c.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        assert [str(ip) for ip in san.get_values_for_type(x509.IPAddress)] == ["127.0.0.1"]
        assert san.get_values_for_type(x509.DNSName) == ["localhost"]
        eku = c.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
        assert set(eku) == {ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH}
        k = serialization.load_pem_private_key(key.read_bytes(), None)
        assert key.read_bytes().startswith(b"-----BEGIN PRIVATE KEY-----")   # PKCS#8, unencrypted
        assert spki(k.public_key()) == spki(c.public_key())
        assert stat.S_IMODE(os.stat(key).st_mode) == 0o600
    assert stat.S_IMODE(os.stat(d / "ca.key").st_mode) == 0o600


def test_make_pki_is_idempotent_and_completes(tmp_path):
    first = make_pki(tmp_path, ["tak", "ea.A2"])
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    lines = []
    again = make_pki(tmp_path, ["tak", "ea.A2", "ea.C"], echo=lines.append)
    assert again["tak"] == first["tak"]
    kept = {n: b for n, b in before.items() if n != "signers.json"}   # it gains ea.C's public key
    assert all((tmp_path / n).read_bytes() == b for n, b in kept.items())   # CA, leaves, signing keys kept
    assert set(json.loads((tmp_path / "signers.json").read_text())["keys"]) == {"tak", "ea.A2", "ea.C"}
    assert [ln.split()[0] for ln in lines] == ["kept", "kept", "kept", "made"]
    cert(again["ea.C"][0]).verify_directly_issued_by(cert(tmp_path / "ca.pem"))
    # a damaged leaf is made again, the CA and the others stay
    again["ea.A2"][1].write_text("garbage")
    make_pki(tmp_path, ["tak", "ea.A2", "ea.C"])
    assert (tmp_path / "ca.pem").read_bytes() == before["ca.pem"]
    assert (tmp_path / "ea.A2.pem").read_bytes() != before["ea.A2.pem"]
    assert (tmp_path / "tak.pem").read_bytes() == before["tak.pem"]
    check_identity(tmp_path, "ea.A2")
    # a missing CA key means a new CA: every leaf is made again, signed by it
    (tmp_path / "ca.key").unlink()
    make_pki(tmp_path, ["tak"])
    assert (tmp_path / "ca.pem").read_bytes() != before["ca.pem"]
    cert(tmp_path / "tak.pem").verify_directly_issued_by(cert(tmp_path / "ca.pem"))
    with pytest.raises(SecurityError, match="ea.C.pem: not signed by the CA"):
        check_identity(tmp_path, "ea.C")
    with pytest.raises(SecurityError, match="bad identity name"):
        make_pki(tmp_path, ["../x"])


def test_check_files_names_the_bad_file(pki, tmp_path):
    d, made = pki
    check_files([d / "ca.pem", *made["tak"]])
    with pytest.raises(SecurityError, match=r"nope\.pem: file missing"):
        check_files([d / "ca.pem", tmp_path / "nope.pem"])
    (tmp_path / "junk.pem").write_text("not a certificate\n")
    with pytest.raises(SecurityError, match=r"junk\.pem: not a PEM certificate"):
        check_files([tmp_path / "junk.pem"])
    (tmp_path / "cut.key").write_text("-----BEGIN PRIVATE KEY-----\nAAAA\n-----END PRIVATE KEY-----\n")
    with pytest.raises(SecurityError, match=r"cut\.key: bad PEM private key"):
        check_files([tmp_path / "cut.key"])
    with pytest.raises(SecurityError, match="is a directory"):
        check_files([tmp_path])
    # a key that is not the certificate's
    other = tmp_path / "o"
    other.mkdir()
    for f in ("ca.pem", "tak.pem"):
        (other / f).write_bytes((d / f).read_bytes())
    (other / "tak.key").write_bytes((d / "observer.key").read_bytes())
    with pytest.raises(SecurityError, match="does not match"):
        check_identity(other, "tak")


# ---------------------------------------------------------------------------- ACL generation

def allowed(acl, cn, flow, message, key):
    """What Zenoh decides, evaluated from the generated section: the subject whose CN it
    is, its policies' rules, a rule allowing when one of its key expressions includes KEY."""
    subj = {s["id"] for s in acl["subjects"] if cn in s.get("cert_common_names", [])}
    rule_ids = {r for p in acl["policies"] if subj & set(p["subjects"]) for r in p["rules"]}
    for r in acl["rules"]:
        if r["id"] in rule_ids and flow in r["flows"] and message in r["messages"] and \
                any(zenoh.KeyExpr(k).includes(zenoh.KeyExpr(key)) for k in r["key_exprs"]):
            assert r["permission"] == "allow"
            return True
    return acl["default_permission"] == "allow"


def test_access_control_is_well_formed(small_sc, pki):
    sc = S.load(SENSORS, events=False)
    groups = sc.meta["fusion"]["groups"]
    units = mesh_units(sc)
    root = "saim/test"
    acl = access_control(root, units, groups, sc.taskorg)   # as secure_config makes them
    assert acl["enabled"] and acl["default_permission"] == "deny"
    ids = [r["id"] for r in acl["rules"]]
    assert len(ids) == len(set(ids))
    subjects = [s["id"] for s in acl["subjects"]]
    assert len(subjects) == len(set(subjects))
    cns = [cn for s in acl["subjects"] for cn in s["cert_common_names"]]
    # each CN exactly one subject; the certificates made for the mesh are the identities the rules know
    assert sorted(cns) == sorted(names_for(sc, consoles=True)) == sorted(subjects)
    pids = [p["id"] for p in acl["policies"]]
    assert len(pids) == len(set(pids))
    for p in acl["policies"]:
        assert set(p["subjects"]) <= set(subjects) and set(p["rules"]) <= set(ids)
    assert {r for p in acl["policies"] for r in p["rules"]} == set(ids)   # no dead rule
    for r in acl["rules"]:
        assert "delete" not in r["messages"] and r["permission"] == "allow"
        for k in r["key_exprs"]:
            assert str(zenoh.KeyExpr(k)) == k and k.startswith(root + "/")
    conf = {"mode": "peer", "transport": {"link": tls_config(pki[0], "tak")}, "access_control": acl}
    zenoh.Config.from_json5(json.dumps(conf))
    # the rules say what the brief says
    r = root
    for cn, msg, key, ok in [
        ("replay", "put", f"{r}/ord/BN", False), ("replay", "put", f"{r}/clock", False),   # no such identity now
        ("source.cp.A", "put", f"{r}/src/cp.A", True), ("source.cp.A", "put", f"{r}/src/cp.B", False),
        ("source.cp.A", "put", f"{r}/ord/BN", False), ("source.cp.A", "put", f"{r}/clock", False),
        ("source.cp.A", "reply", f"{r}/srcj/cp.A", True), ("source.cp.A", "reply", f"{r}/srcj/cp.B", False),
        ("source.fusion.N", "put", f"{r}/src/fusion.N", True), ("source.fusion.N", "put", f"{r}/trk/X1Y1/x4y4/t1", False),
        ("ea.C", "put", f"{r}/ord/BN", False), ("ea.C", "put", f"{r}/clock", False),
        ("ea.C", "put", f"{r}/ord/C", True), ("ea.C", "put", f"{r}/alert/C/late", True),
        ("ea.C", "put", f"{r}/alert/A2/late", False), ("ea.C", "put", f"{r}/ack/C/zid1", True),
        ("ea.C", "put", f"{r}/ack/A2/zid1", False), ("ea.C", "put", f"{r}/msn/C/m1", True),
        ("ea.C", "put", f"{r}/bye/C", True), ("ea.C", "put", f"{r}/bye/A2", False),
        ("ea.C", "liveliness_token", f"{r}/alive/A2/x", False), ("ea.C", "liveliness_token", f"{r}/alive/C/x", True),
        ("ea.C", "declare_queryable", f"{r}/srcj/cp.A", False), ("ea.C", "reply", f"{r}/srcj/cp.A", False),
        ("ea.C", "query", f"{r}/srcj/cp.A", True), ("ea.C", "declare_subscriber", f"{r}/**", True),
        ("ea.C", "query", f"{r}/store/log/main", False), ("ea.C", "put", f"{r}/src/cp.C", False),
        ("ea.C", "delete", f"{r}/ord/C", False), ("ea.C", "put", f"{r}/trk/X1Y1/x4y4/t1", False),
        ("fusion.N", "put", f"{r}/trk/X1Y1/x4y4/t1", False),   # the replay's fusion node: gone
        ("observer", "declare_subscriber", f"{r}/alert/**", True), ("observer", "declare_subscriber", f"{r}/**", False),
        ("observer", "declare_liveliness_subscriber", f"{r}/alive/**", True),
        ("observer", "declare_subscriber", f"{r}/ord/**", False), ("observer", "query", f"{r}/srcj/cp.A", False),
        ("observer", "put", f"{r}/alert/A2/x", False), ("console", "put", f"{r}/cmd/A2", True),
        ("console", "declare_subscriber", f"{r}/src/cp.A", False), ("mallory", "declare_subscriber", f"{r}/**", False),
        ("console.A", "declare_subscriber", f"{r}/src/cp.A", True), ("console.A", "declare_subscriber", f"{r}/clock", False),
        ("ea.C", "put", f"{r}/bye/C", True), ("ea.C", "put", f"{r}/bye/A2", False),
        # the TAK gateway: PLI only as its own source's stream, never a position or an order; of the
        # commands only acknowledgements (an ATAK user's, as its mapped unit: the EA checks that unit)
        ("tak", "put", f"{r}/src/tak", True), ("tak", "put", f"{r}/src/cp.A", False),
        ("tak", "put", f"{r}/ingest/tak", False), ("tak", "put", f"{r}/pos/X1Y1/x4y4/BN/A/A2/A2-1", False),
        ("tak", "put", f"{r}/ord/BN", False), ("tak", "put", f"{r}/cmd/A2/ack/A2", True),
        ("tak", "put", f"{r}/cmd/A2/silence/A2", False), ("tak", "put", f"{r}/dir/A2/order", False),
        ("tak", "put", f"{r}/alert/A2/x", False), ("tak", "declare_subscriber", f"{r}/src/cp.A", True),
        ("ea.A2", "put", f"{r}/src/tak", False),
        ("tak", "declare_subscriber", f"{r}/cmdlog/A2", True), ("tak", "put", f"{r}/cmdlog/A2", False),
    ]:
        assert allowed(acl, cn, "ingress", msg, key) is ok, (cn, msg, key)
    assert allowed(acl, "observer", "egress", "put", f"{r}/ord/BN")   # reads are cut on ingress
    assert not allowed(acl, "ea.C", "egress", "delete", f"{r}/ord/C")


def test_a_console_sends_only_as_its_own_unit():
    """`console.A` may put commands to any EA but only under its own unit's chunk: the EA
    then decides from the hierarchy of the moment (tests/test_signing.py: a peer takes signed
    commands only; tests/test_directives.py: the subtree as organised now)."""
    sc = S.load(SENSORS, events=False)
    r = "saim/test"
    acl = access_control(r, mesh_units(sc), [], sc.taskorg)
    for cn, key, ok in [("console.A", f"{r}/cmd/R/ack/A", True), ("console.A", f"{r}/cmd/A2/set/A", True),
                        ("console.A", f"{r}/cmd/R/ack/BN", False), ("console.A", f"{r}/cmd/A2/ack", False),
                        ("console.BN", f"{r}/cmd/R/ack/BN", True), ("console.R", f"{r}/cmd/R/ack/A", False),
                        ("ea.A", f"{r}/cmd/A2/ack/A", False), ("tak", f"{r}/cmd/A2/ack/A", True),
                        ("tak", f"{r}/cmd/A2/set/A", False)]:   # an ATAK user acks as its mapped unit
        assert allowed(acl, cn, "ingress", "put", key) is ok, (cn, key)


_chunk = st.text(alphabet=string.ascii_letters + string.digits + "_-.", min_size=1, max_size=8)


@settings(max_examples=30, deadline=None)
@given(units=st.sets(_chunk, min_size=1, max_size=6),
       groups=st.sets(_chunk, max_size=3))
def test_access_control_for_any_task_organization(units, groups):
    acl = access_control("saim/h", sorted(units), sorted(groups))
    ids = [r["id"] for r in acl["rules"]]
    assert len(ids) == len(set(ids))
    cns = [cn for s in acl["subjects"] for cn in s["cert_common_names"]]
    # observer, console, tak; an EA and a live source (cp.<unit>) per unit; a fusion node's
    # live source (fusion.<group>) per sensor group
    assert len(cns) == len(set(cns)) == 2 * len(units) + len(groups) + 3
    for g in groups:   # a fusion node's source puts its own stream, and no one else's
        assert allowed(acl, f"source.fusion.{g}", "ingress", "put", f"saim/h/src/fusion.{g}")
        assert all(not allowed(acl, f"source.fusion.{h}", "ingress", "put", f"saim/h/src/fusion.{g}")
                   for h in groups - {g})
        assert all(not allowed(acl, f"source.cp.{u}", "ingress", "put", f"saim/h/src/fusion.{g}") for u in units)
    for u in units:   # each EA puts its own alerts, and no one else's; each source its own stream
        assert allowed(acl, f"ea.{u}", "ingress", "put", f"saim/h/alert/{u}/t")
        assert all(not allowed(acl, f"ea.{v}", "ingress", "put", f"saim/h/alert/{u}/t") for v in units - {u})
        assert allowed(acl, f"source.cp.{u}", "ingress", "put", f"saim/h/src/cp.{u}")
        assert all(not allowed(acl, f"source.cp.{v}", "ingress", "put", f"saim/h/src/cp.{u}") for v in units - {u})
        assert not allowed(acl, f"ea.{u}", "ingress", "put", f"saim/h/src/cp.{u}")
    zenoh.Config.from_json5(json.dumps({"access_control": acl}))


def test_secure_config_checks_before_open(pki, tmp_path):
    d, _ = pki
    units, groups = ["A2", "C"], []
    conf = secure_config(config(listen=[endpoint_tls(free_port())]), d, "ea.A2", "saim/t", units, groups)
    assert json.loads(conf.get_json("transport/link/protocols")) == ["tls"]
    tls = json.loads(conf.get_json("transport/link/tls"))
    assert tls["enable_mtls"] and tls["connect_certificate"] == str(d / "ea.A2.pem")
    assert json.loads(conf.get_json("access_control/default_permission")) == "deny"
    with pytest.raises(SecurityError, match="no subject"):
        secure_config(config(), d, "ea.B", "saim/t", units, groups)
    with pytest.raises(SecurityError, match="not TLS"):
        secure_config(config(connect=["tcp/127.0.0.1:7447"]), d, "ea.A2", "saim/t", units, groups)
    with pytest.raises(SecurityError, match=r"/ca\.pem: file missing"):
        secure_config(config(), tmp_path, "ea.A2", "saim/t", units, groups)
    (tmp_path / "ca.pem").write_bytes((d / "ca.pem").read_bytes())
    with pytest.raises(SecurityError, match=r"/ea\.A2\.pem: file missing"):
        secure_config(config(), tmp_path, "ea.A2", "saim/t", units, groups)
    with pytest.raises(SecurityError, match="bad unit"):
        access_control("saim/t", ["A/B"], [])
    assert endpoint_tls(7447) == "tls/127.0.0.1:7447"


# ---------------------------------------------------------------------------- end to end

class Q(CallbackQueue):
    wait = WAIT


def sample(s):
    return str(s.key_expr), s.payload.to_bytes().decode(), s.kind


def wait_links(session, cns: set[str]):
    """Until SESSION has a link to a peer with each certificate CN of CNS."""
    q = Q()
    seen = set()
    with session.info.declare_link_events_listener(q, history=True):
        end = time.monotonic() + WAIT
        while not cns <= seen:
            ev = q.get(max(0.01, end - time.monotonic()))
            if ev.kind == zenoh.SampleKind.PUT:
                seen.add(ev.link.auth_identifier)
    return seen


def wait_matching(entity):
    """Until a publisher/querier has a matching subscriber/queryable somewhere."""
    q = Q()
    with entity.declare_matching_listener(q):
        if entity.matching_status.matching:
            return
        while not q.get().matching:
            pass


def fail_fast(conf):
    conf.insert_json5("connect/exit_on_failure", "true")
    conf.insert_json5("connect/timeout_ms", "2000")
    return conf


def test_mtls_and_acl_end_to_end(pki, small_sc, tmp_path):
    t_start = time.monotonic()
    d, _ = pki
    units = mesh_units(small_sc)
    groups = sorted(small_sc.meta.get("fusion", {}).get("groups", {}))
    root = f"test/{uuid.uuid4().hex[:8]}"
    p0, p1, p2 = free_port(), free_port(), free_port()

    def conf(name, listen=(), connect=()):
        return secure_config(config(listen=list(listen), connect=list(connect)), d, name, root, units, groups)

    BLOCK = zenoh.CongestionControl.BLOCK
    report = {}
    with zenoh.open(conf("source.cp.A", [endpoint_tls(p0)])) as src, \
            zenoh.open(conf("ea.A2", [endpoint_tls(p1)], [endpoint_tls(p0)])) as a2, \
            zenoh.open(conf("ea.C", [endpoint_tls(p2)], [endpoint_tls(p0), endpoint_tls(p1)])) as c, \
            zenoh.open(conf("observer", connect=[endpoint_tls(p) for p in (p0, p1, p2)])) as obs:
        # a full mesh of direct links (peers do not relay), each authenticated by its CN
        for s, others in ((src, {"ea.A2", "ea.C", "observer"}), (a2, {"source.cp.A", "ea.C", "observer"}),
                          (c, {"source.cp.A", "ea.A2", "observer"}), (obs, {"source.cp.A", "ea.A2", "ea.C"})):
            assert wait_links(s, others) == others
        report["links_s"] = time.monotonic() - t_start

        # --- the observer may read alerts, not orders: its ord/** subscriber is dropped by every
        # peer. Declared before alert/** on the same links, so once a peer has alert/** it has
        # had the chance to take ord/** (a publisher's matching status is what the peer knows).
        obs_alert, obs_ord = Q(), Q()
        keep = [obs.declare_subscriber(f"{root}/ord/**", obs_ord),
                obs.declare_subscriber(f"{root}/alert/**", obs_alert)]
        mark = c.declare_publisher(f"{root}/alert/C/mark", congestion_control=BLOCK)
        probe = src.declare_publisher(f"{root}/alert/probe")
        forged = {k: c.declare_publisher(f"{root}/{k}", congestion_control=BLOCK) for k in ("ord/BN", "src/cp.A")}
        legit = {k: src.declare_publisher(f"{root}/{k}", congestion_control=BLOCK) for k in ("src/cp.A",)}
        wait_matching(mark)
        wait_matching(probe)
        assert not forged["ord/BN"].matching_status.matching

        # --- a forged order and a forged frame of cp.A's stream by ea.C are dropped at A2's ingress
        a2_data = Q()
        keep.append(a2.declare_subscriber(f"{root}/**", a2_data, allowed_origin=zenoh.Locality.REMOTE))
        for p in forged.values():
            wait_matching(p)   # C knows A2's subscriber: its forgeries do go out on the C-A2 link
        for k, p in forged.items():
            p.put(f"forged {k}")
        mark.put("C mark")   # allowed, after the forgeries on the same link
        first = sample(a2_data.get())
        assert first[:2] == (f"{root}/alert/C/mark", "C mark"), first   # nothing of C's came before it
        for k, p in legit.items():
            wait_matching(p)
            p.put(f"legit {k}")
        got = [sample(a2_data.get())[:2] for _ in legit]
        assert got == [(f"{root}/src/cp.A", "legit src/cp.A")]
        assert sample(obs_alert.get())[:2] == (f"{root}/alert/C/mark", "C mark")

        # --- a forged journal (queryable) of cp.A by ea.C is never consulted
        jk = f"{root}/srcj/cp.A"
        keep += [c.declare_queryable(jk, lambda q: q.reply(jk, b"forged journal")),
                 src.declare_queryable(jk, lambda q: q.reply(jk, b"journal"))]

        # --- liveliness: C's token on A2's key is dropped; A2's own is seen by the observer
        a2_alive, obs_alive = Q(), Q()
        keep += [a2.liveliness().declare_subscriber(f"{root}/alive/**", a2_alive, history=True),
                 obs.liveliness().declare_subscriber(f"{root}/alive/**", obs_alive, history=True)]
        c_fake = c.liveliness().declare_token(f"{root}/alive/A2/x")
        c_own = c.liveliness().declare_token(f"{root}/alive/C/m")
        a2_own = a2.liveliness().declare_token(f"{root}/alive/A2/y")
        want_a2 = {f"{root}/alive/C/m"}
        want_obs = want_a2 | {f"{root}/alive/A2/y"}
        seen_a2, seen_obs = set(), set()
        while not want_a2 <= seen_a2:
            seen_a2.add(sample(a2_alive.get())[0])
        while not want_obs <= seen_obs:
            seen_obs.add(sample(obs_alive.get())[0])
        # a liveliness get asks every peer and ends when all have answered: a full snapshot
        now_a2 = {str(r.ok.key_expr) for r in a2.liveliness().get(f"{root}/alive/**", timeout=WAIT) if r.ok}
        now_obs = {str(r.ok.key_expr) for r in obs.liveliness().get(f"{root}/alive/**", timeout=WAIT) if r.ok}
        report["liveliness"] = {"a2": sorted(now_a2), "obs": sorted(now_obs)}
        seen_a2 |= {sample(s)[0] for s in a2_alive.drain()}
        seen_obs |= {sample(s)[0] for s in obs_alive.drain()}
        fake = f"{root}/alive/A2/x"
        assert fake not in seen_a2 | seen_obs | now_a2 | now_obs
        assert want_a2 <= now_a2 and want_obs <= now_obs
        # a token's end (undeclare) passes the ACL: presence still sees leaves
        a2_own.undeclare()
        while (s := sample(obs_alive.get()))[0] != f"{root}/alive/A2/y":
            pass
        assert s[2] == zenoh.SampleKind.DELETE

        # --- the journal: ea.A2's query answered by the source only; the observer's dropped
        t = time.monotonic()
        qa2 = a2.declare_querier(jk, timeout=WAIT, consolidation=zenoh.ConsolidationMode.NONE)
        wait_matching(qa2)
        replies = [r.ok.payload.to_bytes() if r.ok else r.err for r in qa2.get()]
        assert replies == [b"journal"]
        report["a2_query_s"] = time.monotonic() - t
        qobs = obs.declare_querier(jk, timeout=1.0)
        wait_matching(qobs)   # the observer does see the source's queryable ...
        t = time.monotonic()
        assert list(qobs.get()) == []   # ... but the source drops its query
        report["obs_query_s"] = time.monotonic() - t
        assert obs_ord.drain() == []
        assert [sample(s)[:2] for s in a2_data.drain()] == []
        for tok in (c_fake, c_own):
            tok.undeclare()

        # --- a certificate from another CA cannot connect
        rogue_dir = tmp_path / "rogue"
        make_pki(rogue_dir, ["ea.A2"])
        for ca in (rogue_dir / "ca.pem", d / "ca.pem"):   # trusting its own CA, then trusting ours
            rc = fail_fast(config(connect=[endpoint_tls(p0)]))
            rc.insert_json5("transport/link/protocols", '["tls"]')
            for k, v in {"root_ca_certificate": ca, "enable_mtls": True,
                         "connect_certificate": rogue_dir / "ea.A2.pem",
                         "connect_private_key": rogue_dir / "ea.A2.key"}.items():
                rc.insert_json5(f"transport/link/tls/{k}", json.dumps(v if isinstance(v, bool) else str(v)))
            t = time.monotonic()
            with pytest.raises(zenoh.ZError):
                zenoh.open(rc).close()
            report[f"rogue_{ca.parent.name}_s"] = time.monotonic() - t

        # --- plain tcp cannot talk to the tls listener
        t = time.monotonic()
        with pytest.raises(zenoh.ZError):
            zenoh.open(fail_fast(config(connect=[f"tcp/127.0.0.1:{p0}"]))).close()
        report["plain_tcp_s"] = time.monotonic() - t
        assert {ln.auth_identifier for ln in src.info.links()} == {"ea.A2", "ea.C", "observer"}
    report["total_s"] = time.monotonic() - t_start
    print(json.dumps(report, indent=1))
    assert report["total_s"] < 30
