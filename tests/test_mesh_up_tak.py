"""`mesh up --tak URL` on the live mesh (issue 51.1): the Cursor-on-Target gateway is started
and supervised with the rest (secure, its own identity `tak`), and every alert the EAs
raise reaches a TAK server (a TCP receiver reading with pytak) as CoT, XML or TAK protocol
version 1 (protobuf). Refusals of what cannot work are one line, exit 2."""
from __future__ import annotations

import subprocess
import sys

import pytest

from saim_mesh.tak import cot
from saim_mesh.launch.zenoh_config import free_port

from .conftest import SMALL
from .test_tak_gateway import GROUP, Receivers, every_ea_alert_on_tak

pytestmark = pytest.mark.timeout(400)
UNITS = ["A", "A2"]


@pytest.mark.parametrize("proto", ["0", "1"], ids=["xml", "protobuf"])
def test_mesh_up_tak_sends_every_alert_as_cot(tmp_path, proto):
    tport = free_port()
    rx = Receivers(tport, GROUP, free_port())
    out = tmp_path / "mesh"
    try:
        r = subprocess.run([sys.executable, "-m", "saim_mesh", "mesh", "up", str(SMALL), "--units", *UNITS,
                            "--speed", "max", "--out-dir", str(out), "--tak", f"tcp://127.0.0.1:{tport}",
                            "--tak-proto", proto, "--restarts", "0"],
                           capture_output=True, text=True, timeout=340)
        assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
        every_ea_alert_on_tak(rx, [out / f"{u}.jsonl" for u in UNITS])
        raw = [d for s, d in rx.got if s == "tcp"]
        assert all((d[:1] == bytes([cot.STREAM])) == (proto == "1") for d in raw), "every event in the asked protocol"
        kinds = {cot.parse(d).detail.get("__saim", {}).get("kind") for d in raw}
        assert {"unit", "alert"} <= kinds
    finally:
        rx.close()


@pytest.mark.parametrize("args, says", [
    (["--tak-in", "udp://127.0.0.1:6969"], "--tak-in, --tak-uids and --tak-proto go with --tak"),
    (["--tak", "tcp://127.0.0.1:9", "--tak-in", "udp://127.0.0.1:6969"], "--tak-in takes TAK users' PLI on the "
                                                                            "wall clock"),
    (["--tak", "tcp://127.0.0.1:9", "--tak-uids", "/nonexistent/uids.toml"], "no such file"),
])
def test_mesh_up_tak_refuses_what_cannot_work_in_one_line(tmp_path, args, says):
    r = subprocess.run([sys.executable, "-m", "saim_mesh", "mesh", "up", str(SMALL), "--out-dir", str(tmp_path),
                        *args], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and says in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_on_the_wall_clock_the_gateways_pli_are_a_source_every_ea_takes(tmp_path):
    from saim_mesh import scenario as scenarios
    from saim_mesh.deploy.file import Tak
    from saim_mesh.live.up import one_host
    sc = scenarios.load(SMALL, events=False)
    tak = Tak(("tcp://127.0.0.1:9",), ("udp://127.0.0.1:6969",), None, "xml")
    live, _ = one_host(sc, str(SMALL), UNITS, tmp_path, live=True, insecure=True, tak=tak)
    played, _ = one_host(sc, str(SMALL), UNITS, tmp_path, live=False, insecure=True, tak=tak)
    out_only, _ = one_host(sc, str(SMALL), UNITS, tmp_path, live=True, insecure=True,
                           tak=Tak(("tcp://127.0.0.1:9",)))
    assert "tak" in live.sources()                 # PLI on the wall clock: the EAs wait for its watermarks
    assert "tak" not in played.sources()           # a recorded battle: PLI have no event time, refused
    assert "tak" not in out_only.sources()         # CoT out only: nothing to take
