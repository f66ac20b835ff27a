"""Where a benchmark's figures go: one JSON file under bench/results/ (folder made if
absent), optionally echoed, so every bench writes its results the same way."""
from __future__ import annotations

import json
from pathlib import Path


def write(path: str | Path, res: dict, echo: bool = False, indent: int = 1) -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(res, indent=indent) + "\n")
    if echo:
        print(json.dumps(res, indent=indent))
