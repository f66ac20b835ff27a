"""The README is for people: short, no measured figure in its prose (they live in
bench/results/ and docs/benchmarks.md), every file it names exists, its two commands too."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")
FIGURE = re.compile(r"\b\d[\d,.]*\s?(?:ms|s|min|MB|kB|GB|kbit/s|kbps|%|x real time|events/s)(?![\w/])")


def _prose() -> str:
    return re.sub(r"```.*?```", "", README, flags=re.S)


def test_the_readme_is_at_most_150_lines():
    assert len(README.splitlines()) <= 150


def test_the_readme_prose_holds_no_measured_figure():
    assert FIGURE.findall("ran at 13.4x real time in 402 s") == ["13.4x real time", "402 s"]   # the rule bites
    found = [m.group(0) for m in FIGURE.finditer(_prose())]
    assert not found, found


def test_every_path_the_readme_names_exists():
    paths = {p.split(" ")[0] for p in re.findall(r"`((?:docs|scripts|examples|saim_mesh|ea_agent|dissemination|"
                                                   r"tests|configs|bench)/[^`*|\\]*)`", README)}
    assert len(paths) > 10
    missing = sorted(p for p in paths if "<" not in p and not (ROOT / p.rstrip("/")).exists())
    assert not missing, missing


def test_its_two_commands_are_there():
    assert "scripts/demo" in README and "scripts/test" in README
    assert (ROOT / "scripts/demo").exists() and (ROOT / "scripts/test").exists()
