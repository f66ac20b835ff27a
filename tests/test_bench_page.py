"""docs/benchmarks.md is generated from bench/results/ and cannot go stale; every results
file is described; `scripts/bench_tests` reads pytest's report right."""
from __future__ import annotations

import json

import pytest

from benchmarks import page, tests as bench_tests


def test_the_committed_benchmarks_page_is_what_the_results_give():
    assert page.PAGE.read_text(encoding="utf-8") == page.render(), \
        "docs/benchmarks.md is stale: run python -m benchmarks.page"


def test_every_results_file_has_a_row_and_a_figure(tmp_path):
    for p in sorted(page.RESULTS.glob("*.json")):
        r = page.row_for(p.stem)
        assert r is not None, p.name
        assert "(none of its figures found)" not in r.figure(json.loads(p.read_text())), p.name


def test_a_results_file_with_no_row_is_refused_by_name(tmp_path):
    (tmp_path / "mystery.json").write_text("{}")
    with pytest.raises(KeyError, match="mystery.json"):
        page.render(tmp_path)


def test_a_figure_names_what_it_found_and_what_missed():
    d = {"a": {"b": 1.23456}, "ok": {"x": True, "y": False}}
    assert page.fig(d, ("b", "a.b"), ("gone", "a.c"), ("met", "ok")) == "b 1.23; met no: y"


def test_bench_tests_counts_passed_failed_skipped_and_orders_the_slowest(tmp_path):
    x = tmp_path / "j.xml"
    x.write_text('<testsuites><testsuite>'
                 '<testcase classname="tests.test_a" name="t1" time="2.5"/>'
                 '<testcase classname="tests.test_a" name="t2" time="9.0"><failure/></testcase>'
                 '<testcase classname="tests.test_b" name="t3" time="0.1"><skipped/></testcase>'
                 '</testsuite></testsuites>')
    r = bench_tests.parse(x)
    assert (r["tests"], r["passed"], r["failed"], r["skipped"]) == (3, 1, 1, 1)
    assert [s["test"] for s in r["slowest"]] == ["tests/test_a.py::t2", "tests/test_a.py::t1",
                                                 "tests/test_b.py::t3"]
