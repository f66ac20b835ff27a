"""A garbage `--connect` or `--listen` (issue 49.6): one line naming it, exit 2, no
traceback, before any Zenoh session opens; a good endpoint is taken as given."""
from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from saim_mesh.cli.args import _endpoint

from .conftest import SMALL

COMMANDS = {
    "peer": ["peer", "--scenario", str(SMALL), "--unit", "A2"],
    "source": ["source", str(SMALL), "--name", "cp.A"],
    "router": ["router", "--scenario", str(SMALL), "--name", "r"],
    "console": ["console", str(SMALL)],
}


@pytest.mark.timeout(120)
@pytest.mark.parametrize("opt, value", [("--connect", "garbage"), ("--listen", "tcp/127.0.0.1:notaport"),
                                        ("--connect", "carrier-pigeon/roof")])
@pytest.mark.parametrize("cmd", sorted(COMMANDS))
def test_a_garbage_endpoint_is_one_line_and_exit_2(cmd, opt, value):
    r = subprocess.run([sys.executable, "-m", "saim_mesh", *COMMANDS[cmd], opt, value],
                       capture_output=True, text=True, timeout=100)
    assert r.returncode == 2, (r.returncode, r.stderr[-500:])
    assert "Traceback" not in r.stderr + r.stdout
    last = r.stderr.strip().splitlines()[-1]
    assert opt in last and value[:20] in last, last


@pytest.mark.parametrize("ep", ["tcp/127.0.0.1:7447", "tls/localhost:0", "udp/198.18.0.1:7447",
                                "tcp/[::1]:7447", "unixsock-stream//tmp/z.sock", "tcp/127.0.0.1:7447#iface=lo"])
def test_a_good_endpoint_is_taken_as_given(ep):
    assert _endpoint(ep) == ep


@pytest.mark.parametrize("ep", ["", "tcp/", "tcp/127.0.0.1", "tcp/:7447", "tcp/h:99999", "127.0.0.1:7447"])
def test_a_bad_endpoint_is_refused(ep):
    with pytest.raises(argparse.ArgumentTypeError):
        _endpoint(ep)
