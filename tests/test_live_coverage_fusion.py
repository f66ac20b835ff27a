"""A late joiner on a battle with fusion sources, on the live mesh (issue 51.5; the removed
tests/test_fusion.py::test_late_joiner_with_fusion_nodes_alerts_like_in_process): every
source of scenarios/small-sensors (the command posts' and each sensor group's fusion node,
as `saim-mesh sources` lists them) publishes the whole battle before any EA exists; EAs
started then take it all from the sources' journals and raise the in-process alerts."""
from __future__ import annotations

import json
import subprocess
import uuid

import pytest

from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.live.depend import cp_shares
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.launch.zenoh_config import free_port

from .conftest import ROOT
from .test_live import in_process, load, plan_alerts, reap

SENSORS = ROOT / "scenarios" / "small-sensors"
UNITS = ["BN", "A2"]


def sources(sc_path) -> dict[str, list[str]]:
    """`saim-mesh sources SCENARIO`: each source's name and its command's arguments."""
    out = subprocess.run([*py(), "sources", str(sc_path)], capture_output=True, text=True, timeout=60, check=True,
                         env=clean_env()).stdout
    got = {}
    for line in out.splitlines():
        name, cmd = line.split(None, 1)
        argv = cmd.split("#", 1)[0].split()
        assert argv[0] == "saim-mesh", line
        got[name] = argv[1:]
    return got


@pytest.mark.timeout(400)
def test_late_joiners_with_fusion_sources_raise_the_in_process_alerts(tmp_path):
    sc = S.load(SENSORS)
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    srcs = sources(SENSORS)
    assert any(n.startswith("fusion.") for n in srcs), srcs
    procs: list[Proc] = []
    try:
        router = Proc("router", [*py(), "router", "--scenario", str(SENSORS), "--name", "hub", "--listen", ep,
                                 "--root", root], env=clean_env(), log_dir=tmp_path)
        procs.append(router)
        router.wait_for("router ready", 60)
        started = {n: Proc(f"source-{n}", [*py(), *argv, "--connect", ep, "--mode", "client", "--root", root,
                                           "--speed", "max", "--state", str(tmp_path / "state"), "--linger", "600"],
                           env=clean_env(), log_dir=tmp_path) for n, argv in srcs.items()}
        procs += started.values()
        for n, p in started.items():
            p.wait_for(f"end source {n}", 240)   # the whole battle published: every EA joins after it
        # a late joiner takes the whole battle from eight sources' caches: on a loaded machine their
        # history comes in bursts more than the default silence apart, and a source declared lost
        # (and its return) is not what this tests (test_live.py, test_live_partition.py do)
        patient = tmp_path / "patient.toml"
        patient.write_text("[mesh]\nsource_silence_s = 60.0\nsource_join_s = 120.0\n")
        eas = {u: Proc(f"peer-{u}", [*py(), "peer", "--scenario", str(SENSORS), "--unit", u, "--connect", ep,
                                     "--mode", "client", "--root", root, "--sources", *srcs, "--out",
                                     str(tmp_path / f"{u}.jsonl"), "--config", str(patient)],
                       env=clean_env(), log_dir=tmp_path)
               for u in UNITS}
        procs += eas.values()
        summaries = {u: json.loads(p.wait_for("summary ", 240).split(" ", 1)[1]) for u, p in eas.items()}
    finally:
        reap(procs)
    streams = {n: list(play.of_share(sc, sh)) for n, sh in cp_shares(sc).items()}
    assert set(streams) == set(srcs)
    for u in UNITS:
        assert summaries[u]["lost"] == {} and summaries[u]["gaps"] == 0, (u, summaries[u])
        want = plan_alerts(in_process(sc, u, streams))
        assert want and plan_alerts(load(tmp_path / f"{u}.jsonl")) == want, u
    assert any(a[1] in ("contact", "threat") for a in plan_alerts(load(tmp_path / "BN.jsonl")))   # fused tracks
