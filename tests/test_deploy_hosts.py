"""Four "hosts" on one machine (issue 32 items 1-3 end to end): `deploy init` on the
small scenario gives the battalion's command post and its three companies' a host each,
each on its own loopback address (127.X.Y.1-4: Linux answers on all of 127/8), routers
at each linked to the battalion's; `certs --deploy` makes certificates naming those
addresses; one `saim-mesh deploy FILE --host H` process per host, secure (mTLS + access
control), the battalion's host started last, once the companies' sources play. Every EA's
alerts equal the in-process run's. Waits on printed lines; every
child is reaped (and any left named) even when the test fails."""
from __future__ import annotations

import json
import random
import tomllib

import pytest

from saim_mesh import scenario as scenarios
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.inprocess.runner import run

from .conftest import SMALL, stop_supervised

pytestmark = [pytest.mark.timeout(900), pytest.mark.solo]   # wall-clock silence limits: the machine to itself


def plan_alerts(path) -> list[tuple]:
    out = []
    for line in open(path):
        if line.strip():
            d = json.loads(line)
            if d["category"] != "system-problem":
                out.append((d["t"], d["type"], tuple(d["subjects"]), d["message"], d["priority"],
                            d["details"].get("id")))
    return out


def in_process(alerts) -> list[tuple]:
    return [(a.t, a.type, tuple(a.subjects), a.message, a.priority, a.to_json_dict()["details"].get("id"))
            for a in alerts if a.category != "system-problem"]


def assert_hosts_logged_the_in_process_alerts(sc, hosts: dict, out) -> None:
    """Each host's EA peers (`hosts[h]["eas"]`, logs under out/h) logged the plan alerts the
    same units raise in process."""
    units = [u for spec in hosts.values() for u in spec["eas"]]
    want = {ea.owner: in_process(ea.alerts) for ea in run(sc, units)}
    for h, spec in hosts.items():
        for u in spec["eas"]:
            assert plan_alerts(out / h / f"{u}.jsonl") == want[u], (h, u)


def cli(tmp_path, name: str, *args: str) -> Proc:
    return Proc(name, [*py(), *args], env=clean_env(), log_dir=tmp_path / "cli")


def test_four_hosts_on_loopback_each_under_its_own_supervisor_give_the_in_process_alerts(tmp_path):
    sc = scenarios.load(SMALL)
    base = f"127.{random.randrange(1, 255)}.{random.randrange(0, 255)}.0/24"   # no clash with another run
    f = tmp_path / "deploy.toml"
    init = cli(tmp_path, "init", "deploy", "init", str(SMALL), "--out", str(f), "--addresses", base, "--no-consoles")
    assert init.p.wait(120) == 0, init.tail()
    certs = cli(tmp_path, "certs", "certs", "--deploy", str(f))
    assert certs.p.wait(120) == 0, certs.tail()
    doc = tomllib.loads(f.read_text())
    hosts = {h["name"]: h for h in doc["host"]}
    assert list(hosts) == ["BN", "A", "B", "C"]
    procs: dict[str, Proc] = {}
    left: dict[str, list[str]] = {}
    try:
        for h in ["A", "B", "C", "BN"]:   # the companies first: their routers wait for the battalion's
            procs[h] = Proc(f"host-{h}", [*py(), "deploy", str(f), "--host", h, "--out-dir", str(tmp_path / h),
                                          "--quiet"], env=clean_env(), log_dir=tmp_path)
            line = procs[h].wait_for(f"host {h}: routers ", 120)   # each listens on its host's own address
            assert line == f"host {h}: routers r-{h} on tls/{hosts[h]['addresses'][0]}:7447", line
            if h != "BN":   # and plays its source before the battalion's host is up: caught up later
                procs[h].wait_for(f"host {h}: sources cp.{h} started", 120)
        for h, spec in hosts.items():   # the hosts keep running after (others may need their routers)
            n = len(spec["eas"])
            procs[h].wait_for(f"host {h}: {n} of {n} EA peers done", 600)
    finally:
        for h, p in procs.items():
            left[h] = stop_supervised(p, tmp_path / h)
    assert not any(left.values()), f"children still running (killed now): {left}"
    assert_hosts_logged_the_in_process_alerts(sc, hosts, tmp_path)
    summary = json.loads((tmp_path / "A" / "summary.json").read_text())
    assert summary["secure"] and summary["endpoints"]["r-BN"] == f"tls/{hosts['BN']['addresses'][0]}:7447"
