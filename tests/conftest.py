from __future__ import annotations

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
