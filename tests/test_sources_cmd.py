"""`saim-mesh sources SCENARIO`: a scenario's command-post sources and the arguments each
needs (what a by-hand mesh starts), and every source name the docs use has a certificate."""
from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from ea_agent.domains.suo import brigade as B
from ea_agent.core.plan import TaskOrg, Unit
from saim_mesh import scenario as S
from saim_mesh.live.depend import cp_shares
from saim_mesh.security.acl import source_names
from saim_mesh.security.pki import names_for

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ("small", "battalion", "uv-team", "battalion-sensors")


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "saim_mesh", "sources", *args], capture_output=True, text=True,
                          timeout=60, cwd=ROOT)


@pytest.mark.parametrize("name", SCENARIOS)
def test_sources_lists_each_command_post_once_and_they_carry_every_unit_once(name):
    sc = S.load(ROOT / "scenarios" / name, events=False)
    r = _run(str(ROOT / "scenarios" / name), "--json")
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    assert set(got) == set(cp_shares(sc))
    carried = [u for s in got.values() for u in s["units"]]
    assert sorted(carried) == sorted(sc.taskorg.units)    # a partition: nobody twice, nobody left out
    groups = sorted(sc.meta.get("fusion", {}).get("groups", {}))
    assert [n for n, s in got.items() if s["tracks"]] == sorted([f"cp.{sc.taskorg.root}", *(f"fusion.{g}"
                                                                                            for g in groups)])
    ids = set(names_for(sc))
    assert {f"source.{n}" for n in got} <= ids             # each has a certificate


def test_sources_prints_a_runnable_source_line_for_each():
    r = _run("scenarios/small")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert len(lines) == len(cp_shares(S.load(ROOT / "scenarios/small", events=False)))
    a = next(ln for ln in lines if ln.startswith("cp.A "))
    assert "saim-mesh source scenarios/small --name cp.A --units A" in a


def test_sources_of_a_missing_scenario_is_one_line_and_exit_2(tmp_path):
    r = _run(str(tmp_path / "nope"))
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "nope" in r.stderr


def _brigade_names() -> set[str]:
    b = B.build(small=False, seed=7)
    to = TaskOrg([Unit(u["id"], u["name"], u.get("echelon", ""), u["parent"]) for u in b.units])
    return set(source_names(list(to.units), to))


def test_every_source_name_in_the_docs_has_a_certificate():
    known: set[str] = set()
    for name in SCENARIOS:
        sc = S.load(ROOT / "scenarios" / name, events=False)
        known |= {n.removeprefix("source.") for n in names_for(sc) if n.startswith("source.")}
    known |= _brigade_names()
    texts = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "examples").glob("*"))]
    used = {}
    for p in texts:
        if p.is_file():
            for m in re.finditer(r"\bcp\.([A-Za-z0-9]+)\b", p.read_text(encoding="utf-8")):
                used.setdefault(f"cp.{m.group(1)}", p.name)
    assert used, "the docs name no source at all"
    unknown = {n: f for n, f in used.items() if n not in known}
    assert not unknown, f"source names in the docs that no certificate knows: {unknown}"


def test_an_api_source_lingers_on_leaving_while_it_is_asked(monkeypatch, tmp_path):
    from saim_mesh import api
    from saim_mesh.live.source import LiveSource
    stayed = []
    monkeypatch.setattr(LiveSource, "linger", lambda self, least, most, **_: stayed.append((least, most)) or 0.0)
    with api.Source(ROOT / "scenarios/small", "cp.A", listen=["tcp/127.0.0.1:0"], state_dir=tmp_path / "st",
                    linger_s=2.5, linger_max_s=9.0) as src:
        src.watermark(10.0)
    assert stayed == [(2.5, 9.0)]


@pytest.mark.parametrize("bad", [{"linger_s": float("nan")}, {"linger_max_s": -1.0}])
def test_an_api_source_refuses_a_linger_that_is_not_seconds(bad):
    from saim_mesh import api
    with pytest.raises(ValueError, match="linger"):
        api.Source(ROOT / "scenarios/small", "cp.A", listen=["tcp/127.0.0.1:0"], **bad)


def test_the_source_command_lingers_by_default():
    import argparse

    from saim_mesh.cli import mesh
    p = argparse.ArgumentParser()
    mesh.add(p.add_subparsers(dest="cmd"))
    a = p.parse_args(["source", "scenarios/small", "--name", "cp.A"])
    assert a.linger > 0 and a.linger_max >= a.linger
