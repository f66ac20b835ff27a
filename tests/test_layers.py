"""The layers point one way (docs/architecture.md): the core imports neither a domain
nor the application; a domain imports neither another domain, dissemination nor the
application; dissemination imports no domain and not the application. Read from the
source (every import statement, also inside functions), so a test fails the day an
import goes the wrong way."""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOMAINS = sorted(p.name for p in (ROOT / "ea_agent" / "domains").iterdir()
                 if p.is_dir() and (p / "__init__.py").exists())


def imports(path: Path) -> set[str]:
    """Absolute module names a file imports (relative imports resolved)."""
    pkg = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                base = ".".join(p for p in [*parts, base] if p)
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
    return out


def files(folder: str) -> list[Path]:
    return sorted((ROOT / folder).rglob("*.py"))


def offenders(folder: str, forbidden: list[str]) -> list[str]:
    bad = []
    for f in files(folder):
        for m in sorted(imports(f)):
            if any(m == x or m.startswith(x + ".") for x in forbidden):
                bad.append(f"{f.relative_to(ROOT)} imports {m}")
    return bad


def test_the_walker_sees_imports_inside_functions_and_relative_ones(tmp_path):
    """The checker itself: a function-level import and a relative import are seen."""
    f = ROOT / "ea_agent" / "domains" / "suo" / "__init__.py"
    found = imports(f)
    assert "ea_agent.domains.suo.scenario" in found          # imported inside load()
    assert "ea_agent.core.manager" in found


def test_core_imports_no_domain_and_not_the_application():
    assert offenders("ea_agent/core", ["ea_agent.domains", "saim_mesh", "dissemination"]) == []


@pytest.mark.parametrize("domain", DOMAINS)
def test_a_domain_is_one_folder(domain):
    others = [f"ea_agent.domains.{d}" for d in DOMAINS if d != domain]
    assert offenders(f"ea_agent/domains/{domain}", ["saim_mesh", "dissemination", *others]) == []


def test_dissemination_imports_no_domain_and_not_the_application():
    assert offenders("dissemination", ["ea_agent.domains", "saim_mesh"]) == []


def test_there_are_two_domains():
    assert {"suo", "uv"} <= set(DOMAINS)


def test_no_runtime_module_imports_a_benchmark():
    """Benchmarks live in benchmarks/, outside the runtime package, and nothing of the
    runtime imports them (issue 31.6)."""
    assert offenders("saim_mesh", ["benchmarks"]) == []
    assert offenders("dissemination", ["benchmarks"]) == [] and offenders("ea_agent", ["benchmarks"]) == []
    assert not (ROOT / "saim_mesh" / "bench").exists()
    assert not [p.name for p in (ROOT / "saim_mesh").rglob("bench*.py")]


def test_benchmarks_find_the_repository():
    """The benchmarks read scenarios and write bench/results/ under one root, found once
    (benchmarks.ROOT): after the move out of saim_mesh/bench each module computing its own
    from its path got it wrong (two levels up wrote results beside the clone)."""
    import importlib

    import benchmarks
    assert (benchmarks.ROOT / "pyproject.toml").is_file() and (benchmarks.ROOT / "benchmarks").is_dir()
    assert benchmarks.RESULTS == benchmarks.ROOT / "bench" / "results"
    for p in sorted((ROOT / "benchmarks").glob("*.py")):
        if p.name == "__init__.py":
            continue
        assert "__file__" not in p.read_text(), f"{p.name}: finds its own root; use benchmarks.ROOT"
        mod = importlib.import_module(f"benchmarks.{p.stem}")
        assert getattr(mod, "ROOT", benchmarks.ROOT) is benchmarks.ROOT, p.name

# the replay mesh's modules (issue 51: to be deleted): the live mesh must not need them
REPLAY_MESH = [f"saim_mesh.{m}" for m in ("peer", "replay", "offline", "intake", "tickwait", "store", "storeq",
                                          "batch", "keyfacts", "radios", "script", "inbox", "pacer")]


def test_the_live_mesh_and_its_zygote_import_nothing_of_the_replay_mesh():
    """saim_mesh/live/ and the zygote its EA peers fork from (what it preloads and warms
    up: tests/test_zygote.py runs them) name none of the replay mesh's modules."""
    bad = offenders("saim_mesh/live", REPLAY_MESH)
    bad += [f"saim_mesh/zygote.py imports {m}" for m in sorted(imports(ROOT / "saim_mesh" / "zygote.py"))
            if any(m == x or m.startswith(x + ".") for x in REPLAY_MESH)]
    from saim_mesh import zygote
    bad += [f"zygote.PRELOAD has {m}" for m in zygote.PRELOAD if m in REPLAY_MESH or m == "saim_mesh.fusion.peer"]
    assert bad == []
