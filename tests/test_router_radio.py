"""A router keeps forwarding while one of its radio links is full (issue 32). After a
heal, EAs whose sources never crossed the cut fell behind (`bench/results/hosts.json`);
one suspect was head-of-line blocking: a source publishes its frames with BLOCK, and a
router that waited on a full link would hold every other link behind it. This pins down
what the routers do instead. Three namespaced hosts, the project's router in each (h1's
and h2's linked to h0's), h1's link held to 16 kbit/s; a client of h0's router publishes
frames (BLOCK, as `saim-mesh source` does) at 6.4 Mbit/s: the router drops what h1's link
cannot take (the EAs there recover it from the publisher's cache and the source's
journal) and neither the publisher nor h2 waits for h1."""
from __future__ import annotations

import json
import sys

import pytest

from saim_mesh.net import netns
from saim_mesh.net.netns import Hosts
from saim_mesh.launch.proc import wait_line

from .conftest import ROOT, SMALL, wait_until
from .test_netns import ZCLIENT, last, script

WHY = netns.unavailable()
pytestmark = [pytest.mark.timeout(180),
              pytest.mark.skipif(WHY is not None, reason=f"no namespaced hosts here: {WHY}")]
PY = sys.executable
ROOT_KEY = "t/radio"


@pytest.fixture(scope="module", autouse=True)
def no_leftovers():
    netns.cleanup_stale()


def test_a_full_radio_link_holds_neither_the_publisher_nor_the_other_links(tmp_path):
    with Hosts(3) as hs:
        eps = {h: f"tcp/{hs.address(h)}:7447" for h in ("h0", "h1", "h2")}
        resolved = tmp_path / "topology.json"
        resolved.write_text(json.dumps({
            "topology": {"routers": {"r0": {"cp": "BN", "links": []}, "r1": {"cp": "A", "links": ["r0"]},
                                     "r2": {"cp": "B", "links": ["r0"]}}, "attach": {}, "top": "r0"},
            "endpoints": {"r0": eps["h0"], "r1": eps["h1"], "r2": eps["h2"]}}))
        procs = []
        for h, r in (("h0", "r0"), ("h1", "r1"), ("h2", "r2")):
            log = tmp_path / f"{r}.log"
            argv = [PY, "-m", "saim_mesh", "router", "--scenario", str(SMALL), "--name", r, "--root", ROOT_KEY,
                    "--topology", str(resolved), "--listen", eps[h]]
            p = hs.run(h, argv + ([] if r == "r0" else ["--connect", eps["h0"]]), log=log, cwd=ROOT)
            wait_line(log, p, "router ready", 60)
            procs.append(p)
        wait_line(tmp_path / "r0.log", procs[0], "router r2 reachable", 60)
        wait_line(tmp_path / "r0.log", procs[0], "router r1 reachable", 60)
        client = script(tmp_path, "client", ZCLIENT)
        key = f"{ROOT_KEY}/src/cp.X"
        slow, fast, plog = tmp_path / "slow.log", tmp_path / "fast.log", tmp_path / "pub.log"
        for h, log in (("h1", slow), ("h2", fast)):
            p = hs.run(h, [PY, client, "sub", eps[h], key], log=log)
            wait_line(log, p, "subscribed", 60)
            procs.append(p)
        hs.set_rate("h1", 16)
        # an 8 kB frame every 10 ms, BLOCK (6.4 Mbit/s: within seconds past what the kernel's
        # socket buffers, 4 MB, hide)
        pub = hs.run("h0", [PY, client, "pub", eps["h0"], key, "8000", "0.01", "block"], log=plog)
        procs.append(pub)
        wait_until(lambda: last(fast, "got") >= 10 and last(slow, "got") >= 0, 60, "both subscribers served")
        at = last(plog, "pub")
        wait_until(lambda: last(plog, "pub") >= at + 1500, 60, "the publisher goes on (15 s at 100 frames/s)")
        now = last(plog, "pub")
        wait_until(lambda: last(fast, "got") >= now - 50, 10, "h2's subscriber keeps up with the publisher")
        assert last(slow, "got") < now - 500, "h1's link was not full: the test shows nothing"
        for p in procs:
            assert p.poll() is None, f"{p.args} exited {p.returncode}"
