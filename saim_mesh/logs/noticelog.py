"""Re-notifications and escalations as an append-only JSON-lines log beside the alert
log (`<unit>.notify.jsonl`): what the commander was told again, and what reached this
unit from below unacknowledged. Not alerts: the alert log, the counts and `evaluate`
never read it (docs/console.md, "Notifications")."""
from __future__ import annotations

import json
from pathlib import Path

from ea_agent.core.notify import Notice


def path_for(alert_log: str | Path) -> Path:
    """`out/mesh/A2.jsonl` -> `out/mesh/A2.notify.jsonl`."""
    p = Path(alert_log)
    return p.with_name(p.name.removesuffix(".jsonl") + ".notify.jsonl")


def notice_line(n: Notice) -> str:
    return json.dumps(n.to_json_dict(), sort_keys=True, separators=(",", ":"))


class NoticeLog:
    """Flushed after every notice: a killed peer keeps what it told."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.f = open(self.path, "a", encoding="utf-8")
        self.n = 0

    def __call__(self, n: Notice) -> None:
        self.f.write(notice_line(n) + "\n")
        self.f.flush()
        self.n += 1

    def close(self) -> None:
        self.f.close()


def read(path: str | Path) -> list[dict]:
    """The notices of a log (a half-written last line, from a kill, is left out)."""
    out = []
    p = Path(path)
    if not p.exists():
        return out
    for line in p.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            d = json.loads(line)
        except ValueError:
            continue
        if isinstance(d, dict):
            out.append(d)
    return out
