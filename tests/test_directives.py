"""Authority over the mesh (issue 33): a commander's orders flow down its subtree and a
unit's confirmations flow up, each taken by every EA concerned at the same event time.

- in process: orders and a confirmation change what the EAs raise; a console that does
  not command a unit cannot order its mission (refused, with why);
- live: BN's console orders `abort-plan` and `execute-plan withdrawal`, A1's console
  confirms its mission start, C's console orders the end of an A1 mission; every EA peer of
  the subtree takes each at its event time (its command log says so), C's order is refused
  and counted, and every peer's alerts equal an in-process run given the same directives;
- a late-joining peer gets the directives from the other EAs' journals.
"""
from __future__ import annotations

import json
import uuid

import msgspec
import numpy as np
import pytest

from saim_mesh.logs import cmdlog
from saim_mesh.authority import directives as D
from saim_mesh import scenario as S
from saim_mesh.api import Commander
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.inprocess.runner import run
from saim_mesh.launch.zenoh_config import free_port

from .conftest import SMALL
from .test_live import load, plan_alerts, reap, start_source

pytestmark = pytest.mark.timeout(300)
SC = str(SMALL)


@pytest.fixture(scope="module")
def sc():
    return S.load(SMALL)


def hub(tmp) -> tuple[str, str, Proc]:
    """(endpoint, key root, the router process): the test's mesh, the EAs its clients."""
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    return ep, root, Proc("router", [*py(), "router", "--scenario", SC, "--name", "hub", "--listen", ep,
                                     "--root", root], env=clean_env(), log_dir=tmp)


def peer(tmp, unit: str, ep: str, root: str) -> Proc:
    """A live EA peer as a client of the test's router, depending on the one source."""
    return Proc(f"peer-{unit}", [*py(), "peer", "--scenario", SC, "--unit", unit, "--connect", ep, "--mode", "client",
                                 "--root", root, "--sources", "cp.all", "--out", str(tmp / f"{unit}.jsonl")],
                env=clean_env(), log_dir=tmp)


def order(by: str, n: int, at: float, action: str, plan: str = "", mission: str = "") -> D.Taken:
    return D.Taken(by, D.make("order", req=f"r{n}", n=n, at=at, action=action, plan=plan, mission=mission))


def confirm(by: str, n: int, at: float, mission: str, phase: str) -> D.Taken:
    return D.Taken(by, D.make("confirm", req=f"c{n}", n=n, at=at, mission=mission, phase=phase))


def test_orders_down_and_a_confirmation_up_change_what_the_eas_raise(sc):
    units = ["BN", "A", "A1", "C"]
    base = {ea.owner: plan_alerts(ea.alerts) for ea in run(sc, units)}
    dirs = [order("BN", 1, 1500.0, "abort-plan"), order("BN", 2, 1600.0, "execute-plan", plan="withdrawal"),
            confirm("A1", 3, 200.0, "A1-move", "start")]
    got = {ea.owner: plan_alerts(ea.alerts) for ea in run(sc, units, directives=dirs)}
    for u in units:   # the same before the first directive, different after
        assert [a for a in got[u] if a[0] < 200] == [a for a in base[u] if a[0] < 200], u
    assert got["BN"] != base["BN"] and got["A"] != base["A"]
    # the withdrawal plan's missions run after 1600 in BN's subtree
    eas = {ea.owner: ea for ea in run(sc, units, directives=dirs)}
    for u in units:
        assert set(eas[u].domain.missions) == {m.id for m in eas[u].domain.plans["withdrawal"].missions}, u


def test_a_console_that_does_not_command_a_unit_cannot_order_its_mission(sc):
    from saim_mesh.inprocess.runner import config_for, make_ea
    ea = make_ea(sc, "A", config_for(sc, "A"))
    ea.start(0.0)
    ea.advance(2500.0, strict=True)
    bad = order("C", 1, 2500.0, "end-mission", mission="A1-attack")
    assert D.concerns(ea.domain, "A", bad)          # it names A's subordinate's mission: A judges it
    ok, why = D.take(ea, bad)
    assert not ok and "C does not command A1" in why
    assert D.take(ea, order("B", 2, 2500.0, "abort-plan")) is None   # B's own subtree: not A's business
    ok, why = D.take(ea, confirm("A2", 3, 2500.0, "A1-attack", "start"))
    assert not ok and "A1's" in why                 # A2 cannot confirm A1's mission
    ok, why = D.take(ea, order("BN", 4, 2500.0, "execute-plan", plan="nosuch"))
    assert not ok and "unknown plan" in why


def test_bad_directives_are_refused_with_one_line():
    with pytest.raises(ValueError, match="execute-plan names no plan"):
        D.make("order", req="x", n=1, at=10.0, action="execute-plan")
    with pytest.raises(ValueError, match="unknown directive kind"):
        D.make("promote", req="x", n=1, at=10.0)
    with pytest.raises(ValueError):
        D.make("order", req="x", n=1, at=float("nan"), action="abort-plan")
    with pytest.raises(ValueError):
        D.make("confirm", req="x", n=1, at=10.0, mission="A1-move", phase="middle")


def test_live_orders_reach_the_subtree_at_one_event_time_and_equal_in_process(tmp_path, sc):
    units = ["BN", "A", "A1", "C"]
    ep, root, router = hub(tmp_path)
    procs = []
    try:
        router.wait_for("router ready", 60)
        for u in units:
            procs.append(peer(tmp_path, u, ep, root))
        for p, u in zip(procs, units):
            p.wait_for(f"ready {u}", 60)
        cli = Proc("order-cli", [*py(), "order", "--scenario", SC, "--unit", "BN", "--action", "abort-plan",
                                 "--at", "1500", "--connect", ep, "--root", root, "--timeout", "2"],
                   env=clean_env(), log_dir=tmp_path)   # the CLI, a thin layer over the API below
        assert cli.p.wait(60) == 0, cli.tail()
        with Commander(SC, "BN", connect=[ep], root=root) as bn:
            bn.order("execute-plan", at=1600.0, plan="withdrawal", wait_s=0)
        cli = Proc("reorg-cli", [*py(), "order", "--scenario", SC, "--unit", "BN", "--action", "reorganize",
                                 "--target", "A3", "--new-parent", "B", "--at", "1700", "--connect", ep,
                                 "--root", root, "--timeout", "2"], env=clean_env(), log_dir=tmp_path)
        assert cli.p.wait(60) == 0, cli.tail()
        with Commander(SC, "A1", connect=[ep], root=root) as a1:
            a1.confirm_up("A1-move", "start", at=200.0, wait_s=0)
        with Commander(SC, "C", connect=[ep], root=root) as c:
            c.order("end-mission", at=1000.0, mission="A1-move", wait_s=0)
        # a late joiner: A2 starts after the orders were given, and gets them from the others' journals
        procs.append(peer(tmp_path, "A2", ep, root))
        procs[-1].wait_for("ready A2", 60)
        src = start_source(tmp_path, "cp.all", ep, root, "--tracks", "--speed", "max", "--mode", "client")
        procs.append(src)
        lines = {u: p.wait_for("summary ", 180) for p, u in zip(procs, [*units, "A2"])}
    finally:
        reap([*procs, router])
    everyone = [*units, "A2"]
    logged = {u: [c for c in cmdlog.read([tmp_path / f"{u}.cmdlog"]) if isinstance(c.cmd, D.Taken)]
              for u in everyone}
    taken = {u: [(c.cmd.by, c.cmd.d.req, c.t) for c in logged[u]] for u in everyone}
    rows = {u: [json.loads(x) for x in open(tmp_path / f"{u}.cmdlog")] for u in everyone}
    # every EA of BN's subtree took both orders and the reorganization at their event times (none late)
    for u in everyone:
        bn = [(req, t) for by, req, t in taken[u] if by == "BN"]
        assert [t for _, t in bn] == [1500.0, 1600.0, 1700.0], (u, taken[u])   # abort, execute, reorganize
        assert all(r["ok"] and not r["error"] for r in rows[u] if r.get("by") == "BN"), rows[u]
    # A1's confirmation went up to A and BN (and A1's own EA), not to C or to its peer A2
    for u in ("A1", "A", "BN"):
        assert ("A1", 200.0) in [(by, t) for by, _, t in taken[u]], u
    assert all(by != "A1" for by, _, _ in taken["C"] + taken["A2"])
    # C's order for A1's mission: refused at C and at A1's chain, counted there
    for u in ("C", "A", "A1"):
        refused = [r for r in rows[u] if r.get("by") == "C"]
        assert refused and not refused[0]["ok"] and "does not command A1" in refused[0]["error"], (u, rows[u])
        assert json.loads(lines[u].split(" ", 1)[1])["rejects"].get("directive", 0) >= 1, u
    # the same directives in process: the same alerts
    dirs = {c.cmd.d.req: c.cmd for u in everyone for c in logged[u]}
    eas = run(sc, everyone, directives=list(dirs.values()))
    for ea in eas:
        assert plan_alerts(load(tmp_path / f"{ea.owner}.jsonl")) == plan_alerts(ea.alerts), ea.owner


def _ea(sc, unit: str, t: float):
    from saim_mesh.inprocess.runner import config_for, make_ea
    ea = make_ea(sc, unit, config_for(sc, unit))
    ea.start(0.0)
    ea.advance(t, strict=True)
    return ea


def test_a_reorganization_is_taken_by_every_ea_when_the_issuer_commands_both_ends(sc):
    ea = _ea(sc, "C2", 100.0)   # far from it: every EA keeps one chain of command
    mk = lambda by, n, unit, parent: D.Taken(by, D.make("reorganize", req=f"o{n}", n=n, at=100.0, unit=unit,  # noqa: E731
                                                        new_parent=parent))
    ok, why = D.take(ea, mk("A", 1, "A3", "B"))
    assert not ok and "B is not in A's subtree" in why
    ok, why = D.take(ea, mk("C", 2, "A3", "C"))
    assert not ok and "C does not command A3" in why
    ok, why = D.take(ea, mk("BN", 3, "A", "A3"))
    assert not ok and "a cycle" in why
    assert D.take(ea, mk("BN", 4, "A3", "B")) == (True, "")
    ea.advance(102.0)
    assert ea.domain.taskorg.parent["A3"] == "B"


def test_a_call_for_fire_is_confirmed_by_its_requester_or_a_superior_for_every_ea(sc):
    ea = _ea(sc, "C2", 100.0)
    mk = lambda by, n: D.Taken(by, D.make("cff", req=f"f{n}", n=n, at=100.0, cff="F1", requester="A1",  # noqa: E731
                                         lon=10.0, lat=50.0, radius_m=300.0))
    ok, why = D.take(ea, mk("C", 1))
    assert not ok and "C does not command A1" in why
    assert D.take(ea, mk("A", 2)) == (True, "")   # A commands A1; C2's EA warns of its own units near it


def test_a_confirmed_call_for_fire_warns_the_eas_whose_own_units_are_near_its_target(sc):
    """A's confirmation of A1's call for fire, aimed where one of C2's elements stands: C2's
    EA (not in A's chain) warns of its own unit at once (flash, friendly); A3's EA, whose
    units are far from it, raises nothing."""
    def fed(unit: str):   # the scenario's facts up to 100 s: positions known
        ea = _ea(sc, unit, 0.0)
        for ev in sc.events:
            if ev.t >= 100.0:
                break
            ea.submit(ev)
        ea.advance(100.0, strict=True)
        return ea
    near, far = fed("C2"), fed("A3")
    pic, own = near.domain.pic, near.domain.own_leaves
    i = next(i for i, leaf in enumerate(pic.ent_leaf) if leaf in own and np.isfinite(pic.xy[i]).all())
    lon, lat = pic.proj.to_lonlat(float(pic.xy[i, 0]), float(pic.xy[i, 1]))
    cff = D.Taken("A", D.make("cff", req="f1", n=1, at=100.0, cff="F9", requester="A1", lon=float(lon),
                              lat=float(lat), radius_m=150.0))
    for ea in (near, far):
        assert D.take(ea, cff) == (True, "")
        ea.advance(104.0, strict=True)
    warned = [a for a in near.alerts if a.type == "call-for-fire" and a.details.get("cff") == "F9"]
    assert len(warned) == 1 and warned[0].priority == "flash" and warned[0].details["confirmed"], warned
    assert "Planned fire F9" in warned[0].message
    assert not [a for a in far.alerts if a.type == "call-for-fire" and a.details.get("cff") == "F9"]


def test_a_decision_reaches_the_missions_ea_and_a_bad_one_is_refused(sc):
    ea = _ea(sc, "A", 400.0)
    assert D.take(ea, confirm("A1", 9, 400.0, "A1-move", "start")) == (True, "")   # up from A1: it runs
    ea.advance(402.0, strict=True)
    assert ea.domain.plan.state["A1-move"] == "active"
    mk = lambda by, n, option: D.Taken(by, D.make("decide", req=f"d{n}", n=n, at=402.0, alert="A/1",  # noqa: E731
                                                  mission="A1-move", option=option))
    ok, why = D.take(ea, mk("C", 1, "abort"))
    assert not ok and "C does not command A1" in why
    ok, why = D.take(ea, mk("A", 2, "branch:nosuch"))
    assert not ok and "not waiting" in why
    assert D.take(ea, mk("BN", 3, "abort")) == (True, "")
    assert ea.domain.plan.state["A1-move"] == "aborted"
    with pytest.raises(ValueError, match="abort, continue or branch"):
        D.make("decide", req="x", n=1, at=1.0, alert="A/1", mission="A1-move", option="retreat")


def a_plan(sc, end_a1_move: float = 1200.0) -> list[dict]:
    """A's subtree's missions of the main plan, as plan.json lists them, with A1's move due sooner."""
    doc = json.loads((sc.root / "plan.json").read_text())
    out = [dict(m) for m in doc["plans"]["main"] if m["unit"] in ("A", "A1", "A2", "A3")]   # (R leaves A at 0)
    for m in out:
        if m["id"] == "A1-move":
            m["end"] = {**m["end"], "t": end_a1_move}
    return out


def plan(by: str, n: int, at: float, missions, name: str = "A-plan", version: int = 2) -> D.Taken:
    body = missions if isinstance(missions, bytes) else json.dumps(missions).encode()
    return D.Taken(by, D.make("plan", req=f"p{n}", n=n, at=at, name=name, version=version, missions=body))


def test_a_plan_version_is_validated_like_a_plan_file_and_taken_by_the_subtree(sc):
    from saim_mesh.authority.plans import validator
    validate = validator(sc)
    ea = _ea(sc, "A2", 1000.0)
    bad = [*a_plan(sc), {"id": "X-1", "unit": "A2", "type": "move", "params": {"route": "NO-SUCH-ROUTE"}}]
    ok, why = D.take(ea, plan("A", 1, 1000.0, bad), validate)
    assert not ok and "(X-1)" in why and "\n" not in why
    ok, why = D.take(ea, plan("A", 2, 1000.0, b"{not json"), validate)
    assert not ok and "not JSON" in why
    doc = json.loads((sc.root / "plan.json").read_text())
    ok, why = D.take(ea, plan("A", 3, 1000.0, [m for m in doc["plans"]["main"] if m["unit"] == "B1"]), validate)
    assert not ok and "outside A's subtree" in why
    assert ea.domain.plan is not None and "A-plan.v2" not in ea.domain.plans   # the old one stays
    assert D.take(ea, plan("B", 4, 1000.0, a_plan(sc)), validate) is None        # B's plans are not A2's
    assert D.take(ea, plan("A", 5, 1000.0, a_plan(sc)), validate) == (True, "")
    ea.advance(1002.0)
    assert set(ea.domain.missions) == {m["id"] for m in a_plan(sc)}
    assert ea.domain.missions["A1-move"].spec.end.t == 1200.0


def test_live_a_plan_version_reaches_the_subtree_and_a_late_joiner_runs_it(tmp_path, sc):
    units = ["A", "A1"]
    ep, root, router = hub(tmp_path)
    procs = []
    try:
        router.wait_for("router ready", 60)
        procs = [peer(tmp_path, u, ep, root) for u in units]
        for p, u in zip(procs, units):
            p.wait_for(f"ready {u}", 60)
        with Commander(SC, "A", connect=[ep], root=root) as a:
            got = a.publish_plan("A-plan", 2, a_plan(sc), at=1000.0, wait_s=0)
            bad = a.publish_plan("A-plan", 3, [{"id": "X", "unit": "A1", "type": "no-such-class"}], at=1100.0,
                                 wait_s=0)
        assert got == {} and bad == {}   # answers come at the plans' event times
        procs.append(peer(tmp_path, "A2", ep, root))   # joins late: gets the versions from A's and A1's EAs
        procs[-1].wait_for("ready A2", 60)
        procs.append(start_source(tmp_path, "cp.all", ep, root, "--tracks", "--speed", "max", "--mode", "client"))
        for p, u in zip(procs, [*units, "A2"]):
            p.wait_for("summary ", 180)
    finally:
        reap([*procs, router])
    everyone = [*units, "A2"]
    logged = {u: [c for c in cmdlog.read([tmp_path / f"{u}.cmdlog"]) if isinstance(c.cmd, D.Taken)] for u in everyone}
    rows = {u: [json.loads(x) for x in open(tmp_path / f"{u}.cmdlog")] for u in everyone}
    for u in everyone:
        plans = [(r["cmd"]["version"], r["t"], r["ok"]) for r in rows[u] if r["kind"] == "dir.plan"]
        assert plans == [(2, 1000.0, True), (3, 1100.0, False)], (u, rows[u])
        refused = [r for r in rows[u] if r["kind"] == "dir.plan" and not r["ok"]][0]
        assert "no-such-class" in refused["error"] and "\n" not in refused["error"]
    dirs = {c.cmd.d.req: c.cmd for u in everyone for c in logged[u]}
    eas = run(sc, everyone, directives=list(dirs.values()))
    for ea in eas:
        assert set(ea.domain.missions) == {m["id"] for m in a_plan(sc)}, ea.owner
        assert plan_alerts(load(tmp_path / f"{ea.owner}.jsonl")) == plan_alerts(ea.alerts), ea.owner


def test_a_forged_misplaced_replayed_or_unsigned_directive_is_refused_and_counted_in_secure_mode():
    """In secure mode a directive carries authority only under its issuer's own signature:
    console.BN signs BN's orders; C's console signing on BN's key, a forged signature, an
    envelope moved to another key, a replay and an unsigned one are each refused, counted,
    said in one line; the EA goes on."""
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    from saim_mesh.protocol.gate import Gate
    from saim_mesh.live.authority import DirectiveIntake
    from saim_mesh.security import sign as G
    root = "t/dir"
    keys = {n: Ed25519PrivateKey.generate() for n in ("console.BN", "console.C", "ea.A1")}
    pubs = {n: k.public_key() for n, k in keys.items()}
    gate = Gate(5400.0, verifier=G.Verifier(pubs, G.rules_for(pubs), root, require=True))
    intake = DirectiveIntake(root, gate)
    body = msgspec.msgpack.encode(D.make("order", req="r1", n=1, at=1500.0, action="abort-plan"))
    k = D.key(root, "BN", "order")
    good = G.Signer("console.BN", keys["console.BN"]).sign(k, body, 1)
    tk, _ = intake.check(k, good)
    assert tk.by == "BN" and tk.d.action == "abort-plan" and gate.errors == 0
    forged = bytearray(G.Signer("console.BN", keys["console.BN"]).sign(k, body, 4))
    forged[-3] ^= 0x01   # a byte of the signature
    bad = {"misplaced": (k, G.Signer("console.C", keys["console.C"]).sign(k, body, 2)),
           "forged": (k, bytes(forged)),
           "moved": (D.key(root, "BN", "plan"), G.Signer("console.BN", keys["console.BN"]).sign(k, body, 3)),
           "unsigned": (D.key(root, "BN", "order"), msgspec.msgpack.encode(
               D.make("order", req="r9", n=9, at=1500.0, action="abort-plan"))),
           "replayed": (k, good),
           # the good one's exact bytes on another key: not a repeat, a moved envelope
           "copied-to-plan": (D.key(root, "BN", "plan"), good),
           "copied-to-confirm": (D.key(root, "BN", "confirm"), good),
           "copied-to-C": (D.key(root, "C", "order"), good)}
    why = {"misplaced": "console.C may not sign", "forged": "signature", "moved": "signed for",
           "unsigned": "must be signed", "copied-to-plan": "signed for", "copied-to-confirm": "signed for",
           "copied-to-C": "signed for"}
    for what, (key_, payload) in bad.items():
        before = gate.errors
        assert intake.check(key_, payload) is None, what
        if what != "replayed":   # a repeat of a taken directive is dropped, not an attack
            said = gate.rejects.recent[-1]
            assert gate.errors == before + 1 and why[what] in said and "\n" not in said, (what, said)
    assert gate.rejects.by_kind.get("signed", 0) + gate.rejects.by_kind.get("directive", 0) >= 4, gate.rejects.by_kind
    assert tk.d.req == "r1" and len(intake.kept) == 1   # only the good one kept for late joiners


@pytest.mark.parametrize("args, said", [
    (["--action", "reorganize", "--target", "A3"], "--new-parent required"),
    (["--action", "abort-plan", "--plan", "main"], "--plan not used by this action"),
    (["--action", "decide", "--alert", "A1/3", "--mission", "A1-move"], "--option required"),
    (["--action", "start-mission", "--mission", "A1-move", "--target", "A3"], "--target not used"),
])
def test_order_refuses_what_its_action_does_not_read_and_asks_for_what_it_needs(args, said):
    """Nothing a commander writes is silently ignored: one line, exit 2, before any Zenoh
    session opens (the endpoint below has nobody)."""
    import subprocess
    r = subprocess.run([*py(), "order", "--scenario", SC, "--unit", "BN", "--at", "10", *args,
                        "--connect", "tcp/127.0.0.1:9", "--timeout", "1"], capture_output=True, text=True,
                       env=clean_env(), timeout=60)
    assert r.returncode == 2 and said in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_a_plan_version_is_bounded_in_size():
    """A plan's missions over 48 kB are refused when made, and any directive over the
    intake's bound is refused off the wire, counted, before it is decoded."""
    from saim_mesh.protocol.gate import Gate
    from saim_mesh.live.authority import MAX_BYTES, DirectiveIntake
    with pytest.raises(ValueError, match="plan"):
        D.make("plan", req="p", n=1, at=10.0, name="big", version=2, missions=b"[" + b" " * (48 * 1024) + b"]")
    gate = Gate(5400.0)
    intake = DirectiveIntake("t/dir", gate)
    assert intake.check(D.key("t/dir", "A", "plan"), b"\x80" * (MAX_BYTES + 1)) is None
    assert gate.errors == 1 and f"over the {MAX_BYTES} limit" in gate.rejects.recent[-1]
