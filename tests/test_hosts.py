"""The battalion across four namespaced hosts (issue 32): a network namespace per command
post (BN and the three companies) on one bridge, addresses from 198.18.0.0/24, routers
at each, secure (mTLS, access control, certificates naming each host's address); each
host runs `saim-mesh deploy FILE --host H` inside its namespace under its own
supervisor. Every EA's alerts equal the in-process run's. Skipped with one line where
namespaces cannot be made; the namespaces and every process in them are removed even
when the test fails (net/netns.Hosts)."""
from __future__ import annotations

import json
import tomllib

import pytest

from saim_mesh import scenario as scenarios
from saim_mesh.net import netns
from saim_mesh.launch.proc import Proc, clean_env, py

from .conftest import SMALL
from .test_deploy_hosts import assert_hosts_logged_the_in_process_alerts

pytestmark = [pytest.mark.timeout(900), pytest.mark.solo]   # wall-clock silence limits: the machine to itself
WHY = netns.unavailable()


def cli(tmp_path, name: str, *args: str) -> Proc:
    return Proc(name, [*py(), *args], env=clean_env(), log_dir=tmp_path / "cli")


@pytest.mark.skipif(WHY is not None, reason=f"no namespaced hosts here: {WHY}")
def test_the_battalion_over_four_namespaced_hosts_gives_the_in_process_alerts(tmp_path):
    netns.cleanup_stale()
    sc = scenarios.load(SMALL)
    f = tmp_path / "deploy.toml"
    init = cli(tmp_path, "init", "deploy", "init", str(SMALL), "--out", str(f), "--addresses", netns.SUBNET,
               "--no-consoles")
    assert init.p.wait(120) == 0, init.tail()
    certs = cli(tmp_path, "certs", "certs", "--deploy", str(f))
    assert certs.p.wait(120) == 0, certs.tail()
    hosts = {h["name"]: h for h in tomllib.loads(f.read_text())["host"]}
    assert list(hosts) == ["BN", "A", "B", "C"]
    procs: dict[str, Proc] = {}
    with netns.Hosts(list(hosts), log=lambda m: None) as hs:
        for h, spec in hosts.items():   # the file's addresses are the namespaces' own
            assert spec["addresses"][0] == hs.address(h), (h, spec["addresses"], hs.address(h))
        try:
            for h in hosts:
                procs[h] = Proc(f"host-{h}", hs.wrap(h, [*py(), "deploy", str(f), "--host", h, "--out-dir",
                                                        str(tmp_path / h), "--quiet"]),
                                env=clean_env(), log_dir=tmp_path)
            for h, spec in hosts.items():
                line = procs[h].wait_for(f"host {h}: routers ", 120)
                assert f"tls/{spec['addresses'][0]}:" in line, line
            for h, spec in hosts.items():
                n = len(spec["eas"])
                procs[h].wait_for(f"host {h}: {n} of {n} EA peers done", 600)
        finally:
            for p in procs.values():
                p.stop(timeout=60)
        left = {h: hs.pids(h) for h in hosts}
    assert not any(left.values()), f"processes left in the hosts after their supervisors stopped: {left}"
    assert_hosts_logged_the_in_process_alerts(sc, hosts, tmp_path)
    summary = json.loads((tmp_path / "A" / "summary.json").read_text())
    assert summary["secure"]
