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

# the replay mesh's modules, deleted (issue 51): nothing may import them again, and none comes back
REMOVED = [f"saim_mesh.{m}" for m in ("peer", "replay", "offline", "intake", "tickwait", "store", "storeq", "batch",
                                      "keyfacts", "radios", "script", "inbox", "pacer", "presence", "mesh", "reader",
                                      "fusion.peer", "fusion.barrier")]
# and the names in live modules that only the replay used: its clock, store and fusion messages
# (saim_mesh/protocol/wire.py) and KeySpace's keys for them (dissemination/keyspace.py)
REMOVED_NAMES = {"saim_mesh.protocol.wire": ("Health", "Tick", "StoreQuery", "StoreReply", "FusionTick", "FusionQuery",
                                             "FusionReply", "TICK_S", "KEYS_LIMIT", "KeyExprs")}
REMOVED += [f"{mod}.{n}" for mod, names in REMOVED_NAMES.items() for n in names]
REMOVED_KEYS = ("health", "clock", "fusion_store", "fusion_tick", "store", "ingest")   # KeySpace methods
EVERYWHERE = ("saim_mesh", "tests", "benchmarks", "scripts", "examples", "ea_agent", "dissemination")


def removed_imports(paths) -> list[str]:
    return [f"{f.relative_to(ROOT)} imports {m}" for f in paths for m in sorted(imports(f))
            if any(m == x or m.startswith(x + ".") for x in REMOVED)]


def removed_uses(paths) -> list[str]:
    """Uses of a removed name through its module (`W.Tick` where W is the wire module) and of
    a removed KeySpace key (`ks.clock()`, `self.ks.store(...)`): what an import check misses."""
    bad = []
    for f in paths:
        pkg = ".".join(f.relative_to(ROOT).with_suffix("").parts[:-1])
        tree = ast.parse(f.read_text(), str(f))
        alias: dict[str, str] = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                alias.update({a.asname: a.name for a in node.names if a.asname})
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                    base = ".".join(p for p in [*parts, base] if p)
                alias.update({a.asname or a.name: f"{base}.{a.name}" for a in node.names})
        for node in ast.walk(tree):
            if not isinstance(node, ast.Attribute):
                continue
            v = node.value
            if isinstance(v, ast.Name) and node.attr in REMOVED_NAMES.get(alias.get(v.id, ""), ()):
                bad.append(f"{f.relative_to(ROOT)}:{node.lineno} uses {alias[v.id]}.{node.attr}")
            who = v.id if isinstance(v, ast.Name) else v.attr if isinstance(v, ast.Attribute) else ""
            if node.attr in REMOVED_KEYS and who == "ks":
                bad.append(f"{f.relative_to(ROOT)}:{node.lineno} uses KeySpace.{node.attr}")
    return bad


def test_nothing_imports_a_module_of_the_removed_replay_mesh():
    """Every import statement of the tree (also inside functions), scripts without a .py
    suffix included when they are Python: none names a removed module, and none of
    them is back on disk."""
    paths = [f for d in EVERYWHERE for f in files(d)]
    paths += [f for f in sorted((ROOT / "scripts").iterdir()) if f.is_file() and f.suffix != ".py"
              and f.read_text(errors="replace").startswith("#!") and "python" in f.read_text(errors="replace")[:80]]
    assert removed_imports(paths) == []
    assert removed_uses(paths) == []
    back = [m for m in REMOVED if (ROOT / (m.replace(".", "/") + ".py")).exists()]
    assert back == []
    from dissemination.keyspace import KeySpace
    from saim_mesh.protocol import wire
    assert [n for n in REMOVED_NAMES["saim_mesh.protocol.wire"] if hasattr(wire, n)] == []
    assert [k for k in REMOVED_KEYS if hasattr(KeySpace, k)] == []


def test_the_removed_module_check_sees_a_removed_import(tmp_path, monkeypatch):
    """The checker itself: a relative import of a removed module inside a function is seen
    (a probe file in a copy of the layout, never in the tree the other tests read)."""
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    f = tmp_path / "saim_mesh" / "live" / "probe.py"
    f.parent.mkdir(parents=True)
    f.write_text("def f():\n    from ..replay import main_replay\n    from .. import storeq\n")
    assert removed_imports([f]) == ["saim_mesh/live/probe.py imports saim_mesh.replay",
                                    "saim_mesh/live/probe.py imports saim_mesh.replay.main_replay",
                                    "saim_mesh/live/probe.py imports saim_mesh.storeq"]


def test_the_removed_name_check_sees_a_removed_name(tmp_path, monkeypatch):
    """The checker itself: a removed control message, imported by name or used through its
    module's alias, and a removed KeySpace key are seen; a live name beside them is not."""
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    f = tmp_path / "saim_mesh" / "live" / "probe.py"
    f.parent.mkdir(parents=True)
    f.write_text("from ..protocol import wire as W\nfrom saim_mesh.protocol.wire import StoreReply\n"
                 "def f(ks, self):\n    W.make(W.Tick)\n    W.make(W.Ack)\n    self.ks.store()\n    ks.src()\n")
    assert removed_imports([f]) == ["saim_mesh/live/probe.py imports saim_mesh.protocol.wire.StoreReply"]
    assert removed_uses([f]) == ["saim_mesh/live/probe.py:4 uses saim_mesh.protocol.wire.Tick",
                                 "saim_mesh/live/probe.py:6 uses KeySpace.store"]


def test_the_zygote_preloads_nothing_removed():
    from saim_mesh.launch import zygote
    assert [m for m in zygote.PRELOAD if m in REMOVED] == []
