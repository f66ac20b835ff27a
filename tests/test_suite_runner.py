"""tests/suite.py, the runner CI calls: its one report holds both passes' tests, and a bad
SAIM_TEST_WORKERS is one line, not a silent default."""
from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

from . import suite
from .conftest import ROOT


def test_the_two_passes_reports_merge_into_one_with_every_test(tmp_path):
    a, b, out = tmp_path / "a.xml", tmp_path / "b.xml", tmp_path / "out.xml"
    a.write_text('<testsuites><testsuite name="pytest" tests="2"><testcase classname="tests.test_x" name="t1" '
                 'time="1.5"/><testcase classname="tests.test_x" name="t2" time="2"><failure/></testcase>'
                 '</testsuite></testsuites>')
    b.write_text('<testsuites><testsuite name="pytest" tests="1"><testcase classname="tests.test_y" name="t3" '
                 'time="40"/></testsuite></testsuites>')
    suite.merge([a, b, tmp_path / "absent.xml"], out)
    from benchmarks.tests import parse
    got = parse(out)
    assert (got["tests"], got["passed"], got["failed"]) == (3, 2, 1)
    assert got["slowest"][0] == {"test": "tests/test_y.py::t3", "s": 40.0}
    assert len(list(ET.parse(out).getroot())) == 2


def test_each_tests_cpu_with_its_childrens_is_recorded_and_ranked(tmp_path):
    """A test that burns CPU in a child it reaps is charged for it (the conftest's hook):
    bench_tests ranks tests and files by what they cost the machine, not only by wall time."""
    (tmp_path / "conftest.py").write_text((ROOT / "tests" / "conftest.py").read_text())
    (tmp_path / "test_burn.py").write_text(
        "import subprocess, sys, time\n"
        "def test_child_burns():\n"
        "    subprocess.run([sys.executable, '-c', 'import time\\nt = time.process_time()\\n"
        "while time.process_time() - t < 0.6: pass'], check=True)\n"
        "def test_sleeps():\n"
        "    time.sleep(0.6)\n")
    out = tmp_path / "r.xml"
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                        f"--rootdir={tmp_path}", str(tmp_path / "test_burn.py"), f"--junitxml={out}"],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    from benchmarks.tests import parse
    got = parse(out)
    cpu = {x["test"].split("::")[1]: x["cpu_s"] for x in got["slowest_cpu"]}
    assert cpu["test_child_burns"] >= 0.5 and cpu["test_sleeps"] < 0.3, cpu
    assert [x["test"].split("::")[1] for x in got["slowest_cpu"]][0] == "test_child_burns"
    assert got["costliest_files_cpu"][0]["cpu_s"] >= 0.5 and len(got["slowest_files"]) == 1


@pytest.mark.parametrize("raw, why", [("two", "not a whole number"), ("0", "at least 1")])
def test_a_bad_worker_count_is_said_in_one_line(raw, why):
    r = subprocess.run([sys.executable, str(ROOT / "tests" / "suite.py")], capture_output=True, text=True,
                       env={"PATH": "/usr/bin:/bin", "SAIM_TEST_WORKERS": raw}, timeout=60)
    assert r.returncode == 1 and why in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
