"""The whole suite as CI runs it (`scripts/test`): most tests on pytest-xdist workers, a
file to a worker (a module's shared mesh stays in one process), then the `solo` tests alone,
since they time wall-clock limits (a source's silence) that a loaded machine would trip.

With arguments naming what to run (paths, -k, -m, ...), plain pytest on them, serially: a
developer's subset. `--junitxml=FILE` alone keeps the whole suite and writes one report of
both passes (`benchmarks/tests.py` reads it). SAIM_TEST_WORKERS sets the workers (default:
2, or 1 on a one-CPU machine: no xdist)."""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
NO_TESTS = 5   # pytest's exit code when a selection is empty


def workers() -> int:
    raw = os.environ.get("SAIM_TEST_WORKERS")
    if raw is None:
        return min(2, os.cpu_count() or 1)
    try:
        n = int(raw)
    except ValueError:
        raise SystemExit(f"tests/suite.py: SAIM_TEST_WORKERS={raw!r}: not a whole number") from None
    if n < 1:
        raise SystemExit(f"tests/suite.py: SAIM_TEST_WORKERS={n}: at least 1")
    return n


def merge(parts: list[Path], out: Path) -> None:
    """One JUnit report of the passes' reports (each a <testsuites> of <testsuite>s)."""
    root = ET.Element("testsuites")
    for p in parts:
        if p.exists():
            got = ET.parse(p).getroot()
            root.extend(got if got.tag == "testsuites" else [got])
    ET.ElementTree(root).write(out, encoding="utf-8", xml_declaration=True)


def main(argv: list[str]) -> int:
    junit = [a for a in argv if a.startswith("--junitxml=")]
    if len(junit) != len(argv):   # a subset named: as asked, serially
        return subprocess.call([sys.executable, "-m", "pytest", "-q", *argv], cwd=ROOT)
    n = workers()
    with tempfile.TemporaryDirectory() as tmp:
        reports = [Path(tmp) / "parallel.xml", Path(tmp) / "solo.xml"]
        # files in the order conftest.py gives (the costliest first), not by their number of tests
        par = ["-n", str(n), "--dist", "loadfile", "--no-loadscope-reorder"] if n > 1 else []
        rc1 = subprocess.call([sys.executable, "-m", "pytest", "-q", *par, "-m", "not solo",
                               f"--junitxml={reports[0]}"], cwd=ROOT)
        print(f"tests/suite.py: the solo tests, alone (the others: exit {rc1})", flush=True)
        rc2 = subprocess.call([sys.executable, "-m", "pytest", "-q", "-m", "solo", f"--junitxml={reports[1]}"],
                              cwd=ROOT)
        if junit:
            merge(reports, Path(junit[-1].split("=", 1)[1]))
    rc2 = 0 if rc2 == NO_TESTS else rc2
    return rc1 or rc2


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
