"""Every `mesh up` option works on the live mesh (issue 51.2): `--pki` takes the operator's
own certificates (every identity checked first, one line naming what is missing), `--root`
the key root the whole mesh uses."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from .conftest import SMALL

pytestmark = pytest.mark.timeout(300)


def _mesh_up(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "saim_mesh", "mesh", "up", str(SMALL), *args],
                          capture_output=True, text=True, timeout=timeout)


def test_mesh_up_runs_on_the_operators_certificates_and_root(tmp_path):
    pki = tmp_path / "pki"
    r = subprocess.run([sys.executable, "-m", "saim_mesh", "certs", str(SMALL), "--out", str(pki), "--routers", "hub"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    out = tmp_path / "mesh"
    r = _mesh_up("--units", "A2", "--speed", "max", "--out-dir", str(out), "--pki", str(pki), "--root", "test/mine",
                 "--restarts", "0")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    host = json.loads((out / "host.json").read_text())
    assert not (out / "pki").exists() and host["pki"] == str(pki)       # none made: the operator's were used
    assert host["deployment"]["root"] == "test/mine"
    assert sum(1 for x in open(out / "A2.jsonl") if x.strip()) >= 5


def test_mesh_up_refuses_certificates_that_lack_an_identity_in_one_line(tmp_path):
    pki = tmp_path / "pki"
    subprocess.run([sys.executable, "-m", "saim_mesh", "certs", str(SMALL), "--out", str(pki)], check=True,
                   capture_output=True, timeout=120)   # no router identity
    r = _mesh_up("--units", "A2", "--out-dir", str(tmp_path / "mesh"), "--pki", str(pki), timeout=60)
    assert r.returncode == 2, r.stdout + r.stderr
    line = r.stderr.strip()
    assert len(line.splitlines()) == 1 and "router.hub" in line and "--routers hub" in line, line


def test_mesh_up_refuses_pki_with_insecure(tmp_path):
    r = _mesh_up("--out-dir", str(tmp_path), "--pki", str(tmp_path), "--insecure", timeout=60)
    assert r.returncode == 2 and "--pki and --insecure" in r.stderr
