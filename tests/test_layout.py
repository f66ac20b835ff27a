"""saim_mesh/ is laid out by the flow (docs/architecture.md, "Where the code is"): a folder a
stage, few modules loose at its top, no module that the product does not use, and no module
so long it likely does two jobs. Read from the source, like tests/test_layers.py."""
from pathlib import Path

from .test_layers import ROOT, imports

TOP_MAX = 12         # modules loose at saim_mesh/'s top
LONG = 400           # lines: a module this long likely does two jobs
LONG_ALLOWED = 3     # modules over LONG in the whole product, each one job


def _stage(mod: str) -> str | None:
    parts = mod.split(".")
    if parts[0] != "saim_mesh" or len(parts) < 2:
        return None
    return parts[1] if (ROOT / "saim_mesh" / parts[1]).is_dir() else "(top)"


def test_few_modules_are_loose_at_the_top():
    loose = sorted(p.name for p in (ROOT / "saim_mesh").glob("*.py") if p.name not in ("__init__.py", "__main__.py"))
    assert len(loose) <= TOP_MAX, f"{len(loose)} modules at saim_mesh/'s top (at most {TOP_MAX}): {loose}"


def test_the_protocol_imports_no_other_stage():
    """What crosses the mesh (messages, control messages, the gate) is the bottom stage:
    every other one reads it, it reads none of them."""
    bad = [f"{f.relative_to(ROOT)} imports {m}" for f in sorted((ROOT / "saim_mesh" / "protocol").rglob("*.py"))
           for m in sorted(imports(f)) if _stage(m) not in (None, "protocol")]
    assert bad == []


def test_only_the_command_line_imports_the_command_line():
    """The CLI parses and calls the public API and the stages; nothing below calls back up
    into it. Its two entry points run it: `python -m saim_mesh` and the EA fork server, whose
    forked children each run one `saim-mesh peer` command line."""
    entries = {"saim_mesh/__main__.py", "saim_mesh/launch/zygote.py"}
    bad = [f"{f.relative_to(ROOT)} imports {m}" for f in sorted((ROOT / "saim_mesh").rglob("*.py"))
           if _stage(".".join(f.relative_to(ROOT).with_suffix("").parts)) != "cli"
           and str(f.relative_to(ROOT)) not in entries
           for m in sorted(imports(f)) if _stage(m) == "cli"]
    assert bad == []


def test_the_product_imports_no_benchmark():
    bad = [f"{f.relative_to(ROOT)} imports {m}" for f in sorted((ROOT / "saim_mesh").rglob("*.py"))
           for m in sorted(imports(f)) if m == "benchmarks" or m.startswith("benchmarks.")]
    assert bad == []


def test_few_modules_are_long():
    long = sorted((n, str(f.relative_to(ROOT))) for d in ("saim_mesh", "ea_agent", "dissemination")
                  for f in (ROOT / d).rglob("*.py") if (n := len(f.read_text().splitlines())) > LONG)
    assert len(long) <= LONG_ALLOWED, f"{len(long)} modules over {LONG} lines (at most {LONG_ALLOWED}): {long}"
