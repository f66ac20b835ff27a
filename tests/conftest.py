from __future__ import annotations

import json
import os
import resource
import signal
import time
from pathlib import Path

import pytest

from saim_mesh import scenario as S
from saim_mesh.inprocess.runner import run

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "scenarios" / "small"
BATTALION = ROOT / "scenarios" / "battalion"


_CPU0 = pytest.StashKey[float]()


def _file_costs() -> dict[str, float]:
    """Seconds each test file took in the last measured suite run (bench/results/tests.json):
    its slowest files and its slowest tests summed per file; nothing when it cannot be read."""
    try:
        res = json.loads((ROOT / "bench" / "results" / "tests.json").read_text())
    except (OSError, ValueError):
        return {}
    costs: dict[str, float] = {}
    for t in res.get("slowest", []):
        f = str(t.get("test", "")).split("::")[0]
        costs[f] = costs.get(f, 0.0) + float(t.get("s", 0.0))
    for f in res.get("slowest_files", []):
        costs[str(f.get("file"))] = max(costs.get(str(f.get("file")), 0.0), float(f.get("s", 0.0)))
    return costs


def pytest_collection_modifyitems(session, config, items):
    """The costliest files first, each file's tests in their own order (a module's shared
    mesh stays whole): on xdist workers taking a file at a time (tests/suite.py), a long file
    taken last would leave the other worker idle while it runs."""
    costs = _file_costs()
    if costs:
        items.sort(key=lambda it: -costs.get(it.nodeid.split("::")[0], 0.0))   # stable: ties keep their order


def _cpu_s() -> float:
    """CPU of this process and of every child it has reaped (a test's meshes included)."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item):
    item.stash[_CPU0] = _cpu_s()
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Each test's CPU (setup to teardown, its processes' too) as a JUnit property `cpu_s`:
    on a machine the suite keeps busy, what a test costs is its CPU, not its wall time
    (benchmarks/tests.py ranks by both)."""
    outcome = yield
    if call.when == "teardown" and _CPU0 in item.stash:
        outcome.get_result().user_properties.append(("cpu_s", round(_cpu_s() - item.stash[_CPU0], 2)))


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
