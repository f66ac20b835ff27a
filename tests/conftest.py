from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import pytest

from saim_mesh import scenario as S
from saim_mesh.inprocess.runner import run

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "scenarios" / "small"
BATTALION = ROOT / "scenarios" / "battalion"


def wait_until(pred, timeout: float, what: str) -> None:
    """Poll a condition until a deadline: the test fails naming what never happened."""
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > end:
            raise AssertionError(f"within {timeout} s: {what}")
        time.sleep(0.005)


@pytest.fixture(scope="session")
def small():
    return S.load(SMALL)


@pytest.fixture(scope="session")
def small_run(small):
    """The default EAs over the small scenario, once for the whole session."""
    eas = run(small, ["BN", "A", "B", "C", "A2"])
    return {ea.owner: ea for ea in eas}


def alerts_of(run_, owner, typ=None):
    return [a for a in run_[owner].alerts if typ is None or a.type == typ]


def stop_supervised(p, out) -> list[str]:
    """SIGTERM to a supervisor (`mesh up`, `deploy --host`), time for it to stop its children
    (more than Proc.stop's 5 s), then any child still alive (its `pids.json`) is named and
    killed: none may outlive the test."""
    p.stop(timeout=90)
    pids = json.loads((out / "pids.json").read_text()) if (out / "pids.json").exists() else {}
    left = []
    for name, pid in pids.items():
        try:
            os.kill(int(pid), 0)
            if not open(f"/proc/{int(pid)}/stat").read().split(") ", 1)[1].startswith("Z"):
                left.append(name)
                os.kill(int(pid), signal.SIGKILL)
        except (ProcessLookupError, ValueError, TypeError, FileNotFoundError):
            pass
    return left
