"""The by-hand recipe (`examples/by_hand.sh`): a router, several EA peers and a scenario's
command-post sources started one command at a time, open and secure. Each EA raises what
an in-process EA fed the same sources in (event time, source) order raises. The script's
whole process group is killed whatever happens."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.live.depend import cp_shares
from saim_mesh.launch.zenoh_config import free_port

from .conftest import SMALL
from .test_live import in_process, load, plan_alerts

pytestmark = pytest.mark.timeout(400)
ROOT = Path(__file__).resolve().parent.parent
UNITS = ("BN", "A", "A2")


@pytest.fixture(scope="module")
def sc():
    return S.load(SMALL)


@pytest.mark.parametrize("secure", [False, True], ids=["open", "secure"])
def test_the_by_hand_recipe_runs_several_eas_a_router_and_the_sources(tmp_path, sc, secure):
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    out = tmp_path / "mesh"
    cmd = [str(ROOT / "examples/by_hand.sh"), *(["--secure"] if secure else []), str(SMALL), str(out),
           str(free_port()), *UNITS]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=ROOT,
                         start_new_session=True)
    try:
        said, _ = p.communicate(timeout=360)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    assert p.returncode == 0, said
    streams = {n: list(play.of_share(sc, sh)) for n, sh in cp_shares(sc).items()}
    for u in UNITS:
        assert f"{u}: " in said
        want = plan_alerts(in_process(sc, u, streams))
        got = plan_alerts(load(out / f"{u}.jsonl"))
        assert len(want) >= 5 and got == want, u
    if secure:
        assert (out / "pki" / "router.hub.pem").exists()   # the router's own identity, made by the recipe
