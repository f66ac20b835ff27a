"""Confirmations an EA infers flow up (issue 33, item 4): when a unit crosses its line of
departure with no confirmation of its mission's start, its own EA starts the mission
(the plan says crossing is its start) and, on the live mesh, publishes that confirmation
signed as itself; its superiors' EAs take it.

- in process: a superior that did not see the crossing (no reports from the unit) starts
  the mission on the confirmation at its time; one that saw it already knows, and its
  alerts do not change;
- live: A1's peer publishes `A1-attack start` once, A's and BN's peers take it (command
  log), A2's (not a superior) does not, and every peer's alerts equal in process.
"""
from __future__ import annotations

import gzip
import json
import shutil
import time
import uuid
from datetime import datetime, timezone
from pathlib import Path

import pytest

from saim_mesh.logs import cmdlog
from saim_mesh.authority import directives as D
from saim_mesh import scenario as S
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.inprocess.runner import run
from saim_mesh.launch.zenoh_config import free_port

from .conftest import SMALL
from .test_live import load, plan_alerts, reap

pytestmark = pytest.mark.timeout(300)
MISSION = "A1-attack"
UNTIL = 2600   # the source stops here (A1 crosses its line at 2456)
SPEED = 50
PACED_FROM = 1800   # the source's clock reads this when it is started (what came before, at once):
                    # the crossing and the confirmation's time paced at SPEED, 16 s of wall time


def rewrite(dst: Path, keep) -> Path:
    """The small battle with only the events `keep` accepts (a scenario folder at `dst`)."""
    shutil.copytree(SMALL, dst)
    lines = gzip.open(Path(SMALL) / "events.jsonl.gz", "rt").read().splitlines()
    kept = [x for x in lines if keep(json.loads(x))]
    assert len(kept) < len(lines)
    with gzip.open(dst / "events.jsonl.gz", "wt") as f:
        f.write("\n".join(kept) + "\n")
    return dst


def unconfirmed(d: dict) -> bool:
    """Everything but the scripted start of A1's attack: A1 crossing its line starts it."""
    return not (d.get("kind") == "mission" and d["mission"] == MISSION and d["phase"] == "start")


@pytest.fixture(scope="module")
def noconf(tmp_path_factory) -> Path:
    return rewrite(tmp_path_factory.mktemp("sc") / "small-noconf", unconfirmed)


def confirm(at: float) -> D.Taken:
    return D.Taken("A1", D.make("confirm", req="up1", n=1, at=at, mission=MISSION, phase="start"))


def test_an_ea_starts_its_mission_on_crossing_its_line_and_superiors_that_saw_it_already_know(noconf):
    sc = S.load(noconf)
    told = []
    eas = run(sc, ["BN", "A", "A1"])
    for ea in eas:   # each saw A1 cross PL-BLUE-A: the mission started there without a confirmation
        assert ea.domain.plan.started.get(MISSION) is not None, ea.owner
    t = eas[0].domain.plan.started[MISSION]
    at = (t // eas[0].epoch_s + 1) * eas[0].epoch_s
    with_it = run(sc, ["BN", "A", "A1"], directives=[confirm(at)])
    for a, b in zip(eas, with_it):   # a confirmation of what it knew changes nothing
        assert plan_alerts(a.alerts) == plan_alerts(b.alerts), a.owner
        assert b.domain.plan.started[MISSION] == t
    # the hook the live peer publishes from: called once, by the unit's own EA, with the start
    from saim_mesh.inprocess.runner import config_for, make_ea
    ea = make_ea(sc, "A1", config_for(sc, "A1"))
    ea.domain.inferred.append(told.append)
    ea.start(0.0)
    for m in sc.events:
        ea.submit(m)
    ea.finish(sc.duration_s)
    assert [(c.mission, c.phase, c.t) for c in told] == [(MISSION, "start", t)]


def test_a_superior_that_did_not_see_the_crossing_starts_the_mission_on_the_confirmation(noconf, tmp_path):
    a1 = {e for e, u in S.load(SMALL).taskorg.entity_unit.items() if u.startswith("A1")}
    blind = rewrite(tmp_path / "blind", lambda d: unconfirmed(d) and d.get("entity") not in a1)
    sc = S.load(blind)
    (bn,) = run(sc, ["BN"])
    assert bn.domain.plan.started.get(MISSION) is None   # no report of A1: nothing to see it by
    (bn,) = run(sc, ["BN"], directives=[confirm(2458.0)])
    assert bn.domain.plan.started[MISSION] == 2458.0


def test_live_an_inferred_start_is_published_up_once_and_taken_by_the_superiors(noconf, tmp_path):
    sc_path = str(noconf)
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    units = ["BN", "A", "A1", "A2"]
    router = Proc("router", [*py(), "router", "--scenario", sc_path, "--name", "hub", "--listen", ep,
                             "--root", root], env=clean_env(), log_dir=tmp_path)
    procs = []
    try:
        router.wait_for("router ready", 60)
        for u in units:
            procs.append(Proc(f"peer-{u}", [*py(), "peer", "--scenario", sc_path, "--unit", u, "--connect", ep,
                                            "--mode", "client", "--root", root, "--sources", "cp.all",
                                            "--out", str(tmp_path / f"{u}.jsonl")], env=clean_env(), log_dir=tmp_path))
        for p, u in zip(procs, units):
            p.wait_for(f"ready {u}", 60)
        start = datetime.fromtimestamp(time.time() - PACED_FROM / SPEED, timezone.utc).isoformat()
        procs.append(Proc("source-cp.all", [*py(), "source", sc_path, "--name", "cp.all", "--connect", ep,
                                            "--root", root, "--linger", "600", "--tracks", "--speed", str(SPEED),
                                            "--start", start, "--until", str(UNTIL), "--mode", "client"],
                          env=clean_env(), log_dir=tmp_path))
        for p, u in zip(procs, units):
            p.wait_for("summary ", 180)
    finally:
        reap([*procs, router])
    said = [x for x in (tmp_path / "peer-A1.log").read_text().splitlines() if "confirmed up:" in x]
    assert len(said) == 1 and f"{MISSION} start" in said[0], said
    taken = {u: [c for c in cmdlog.read([tmp_path / f"{u}.cmdlog"]) if isinstance(c.cmd, D.Taken)]
             for u in units}
    rows = {u: [json.loads(x) for x in open(tmp_path / f"{u}.cmdlog")] for u in units}
    seen = float(said[0].split("seen at ")[1].split(")")[0])
    at = float(said[0].split(" at ")[1].split(" ")[0])
    assert at >= seen + D.CONFIRM_LEAD_S and at % 2.0 == 0.0, said   # ahead, on an epoch's end
    for u in ("A1", "A", "BN"):   # its own EA and its superiors' took it, once, ok
        ups = [c for c in taken[u] if c.cmd.by == "A1"]
        assert len(ups) == 1 and ups[0].cmd.d.mission == MISSION and ups[0].cmd.d.phase == "start", (u, ups)
        res = [r for r in rows[u] if r.get("by") == "A1" and r["cmd"].get("mission") == MISSION]
        assert len(res) == 1 and res[0]["ok"], rows[u]
        # at its time, or (a machine too loaded to keep up at SPEED) said to be late
        assert ups[0].t == at or "taken late" in res[0]["error"], (u, ups[0].t, res)
    assert not [c for c in taken["A2"] if c.cmd.by == "A1"]   # a peer, not a superior
    sc = S.load(noconf)
    for ea in run(sc, units):   # those that saw the crossing knew: the same alerts (up to the source's end)
        got = [a for a in plan_alerts(load(tmp_path / f"{ea.owner}.jsonl")) if a[0] <= UNTIL]
        assert got == [a for a in plan_alerts(ea.alerts) if a[0] <= UNTIL], ea.owner
