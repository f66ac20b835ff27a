"""The test suite as CI runs it (`scripts/test`), timed: how many tests, how many passed and
were skipped, the wall time, and the slowest tests, so the suite's cost is watched like any
other figure (bench/results/tests.json).

Per-test seconds come from pytest's JUnit XML (setup, call and teardown together, as a
test's share of the run); the wall time is the whole command's, installation excluded when
the environment is already set up.
"""
from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from . import RESULTS, ROOT

SLOWEST = 25


def parse(junit: Path) -> dict:
    """Counts and per-test seconds from a JUnit XML report."""
    root = ET.parse(junit).getroot()
    cases = []
    cpu: dict[str, float] = {}
    failed = skipped = 0
    for tc in root.iter("testcase"):
        name = f"{tc.get('classname', '').replace('.', '/')}.py::{tc.get('name')}"
        cases.append((name, float(tc.get("time") or 0.0)))
        for prop in tc.iter("property"):
            if prop.get("name") == "cpu_s":
                cpu[name] = float(prop.get("value") or 0.0)
        kinds = {c.tag for c in tc}
        if kinds & {"failure", "error"}:
            failed += 1
        elif "skipped" in kinds:
            skipped += 1
    cases.sort(key=lambda c: -c[1])
    by_cpu = sorted(cpu.items(), key=lambda c: -c[1])

    def by_file(pairs) -> list[tuple[str, float]]:
        files: dict[str, float] = {}
        for n, s in pairs:
            f = n.split("::")[0]
            files[f] = files.get(f, 0.0) + s
        return sorted(files.items(), key=lambda c: -c[1])[:SLOWEST]
    return {"tests": len(cases), "passed": len(cases) - failed - skipped, "failed": failed, "skipped": skipped,
            "slowest": [{"test": n, "s": round(s, 2)} for n, s in cases[:SLOWEST]],
            "sum_test_s": round(sum(s for _, s in cases), 1),
            "slowest_cpu": [{"test": n, "cpu_s": s} for n, s in by_cpu[:SLOWEST]],
            "slowest_files": [{"file": f, "s": round(s, 1)} for f, s in by_file(cases)],
            "costliest_files_cpu": [{"file": f, "cpu_s": round(s, 1)} for f, s in by_file(cpu.items())],
            "sum_cpu_s": round(sum(cpu.values()), 1)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(ROOT / "bench/results/tests.json"))
    ap.add_argument("pytest_args", nargs="*", help="passed to pytest (default: the whole suite)")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        junit = Path(tmp) / "junit.xml"
        t0 = time.monotonic()
        rc = subprocess.call([str(ROOT / "scripts/test"), f"--junitxml={junit}", *a.pytest_args], cwd=ROOT)
        wall = time.monotonic() - t0
        if not junit.exists():
            print(f"bench_tests: pytest wrote no report (exit {rc})", file=sys.stderr)
            return rc or 1
        res = parse(junit)
    res = {**res, "wall_s": round(wall, 1), "exit_code": rc, "target_wall_s": 1200,
           "met": rc == 0 and wall <= 1200, "machine": platform.machine(), "python": platform.python_version(),
           "note": "scripts/test as CI runs it; `slowest`: setup, call and teardown of each test; "
                   "`*_cpu`: CPU of the test's process and the children it reaped"}
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(f"{res['tests']} tests, {res['passed']} passed, {res['skipped']} skipped, {res['failed']} failed, "
          f"{wall:.0f} s wall: {a.out}")
    if Path(a.out).resolve().parent == RESULTS.resolve():
        from . import page
        page.main([])   # the page shows the new figure
    return rc


if __name__ == "__main__":
    raise SystemExit(main())
