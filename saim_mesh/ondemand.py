"""Scenarios too large to commit, generated on first use and whenever their generator changed.

`ensure("brigade", root)` returns root/brigade, generating it when it is absent or stale:
its stamp file (STAMP) holds the generator's arguments and a hash of the generator's source
files, so a change to the generator or the oracle makes a fresh one. Generation goes to a
temporary folder renamed into place under a lock: a reader never sees half a scenario.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
from pathlib import Path

from ea_agent.domains import suo

STAMP = "generated.json"
VARIANTS: dict[str, dict] = {"brigade": {"brigade": True, "small": False, "seed": 7},
                             "brigade-small": {"brigade": True, "small": True, "seed": 7}}
_SUO = Path(suo.__file__).resolve().parent
# what the files of a generated scenario depend on: the generators and the oracle
SOURCES = [_SUO / "generator.py", _SUO / "random_battle.py", _SUO / "brigade.py", *sorted((_SUO / "oracle").glob("*.py")),
           _SUO.parents[1] / "core" / "geo.py"]


def source_hash() -> str:
    """SHA-256 over the generator's source files (names and contents)."""
    h = hashlib.sha256()
    for p in SOURCES:
        h.update(str(p.relative_to(_SUO.parents[2])).encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def stamp_for(name: str) -> dict:
    return {"name": name, "args": VARIANTS[name], "source_sha256": source_hash()}


def is_fresh(path: Path, name: str) -> bool:
    """Whether `path` holds `name` made by today's generator with today's arguments."""
    try:
        return json.loads((path / STAMP).read_text()) == stamp_for(name)
    except (OSError, ValueError):
        return False


def _generate(out: Path, args: dict) -> dict:
    return suo.generate(out, **args)


def ensure(name: str, out_root: Path) -> Path:
    """out_root/<name>, generated first when absent or stale."""
    if name not in VARIANTS:
        raise ValueError(f"no on-demand scenario {name!r}: one of {', '.join(sorted(VARIANTS))}")
    out_root = Path(out_root)
    path = out_root / name
    if is_fresh(path, name):
        return path
    out_root.mkdir(parents=True, exist_ok=True)
    with open(out_root / f".{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)   # another process may be making it right now
        if is_fresh(path, name):
            return path
        tmp = out_root / f".{name}.tmp-{os.getpid()}"
        shutil.rmtree(tmp, ignore_errors=True)
        _generate(tmp, VARIANTS[name])
        (tmp / STAMP).write_text(json.dumps(stamp_for(name), indent=1) + "\n")
        shutil.rmtree(path, ignore_errors=True)
        os.replace(tmp, path)
    return path
