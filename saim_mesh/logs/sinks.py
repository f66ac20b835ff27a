"""Where alerts go: terminal (coloured by priority), JSON lines, a list in memory."""
from __future__ import annotations

import json
import sys
from typing import IO

from ea_agent.core.alert import hms

from ..protocol.messages import Alert

COLOURS = {"flash": "\033[1;97;41m", "immediate": "\033[1;31m", "priority": "\033[33m", "routine": "\033[36m"}
RESET = "\033[0m"


def alert_line(a: Alert) -> str:
    return json.dumps(a.to_json_dict(), sort_keys=True, separators=(",", ":"))


class TerminalSink:
    def __init__(self, stream: IO[str] | None = None, colour: bool | None = None):
        self.stream = stream or sys.stdout
        self.colour = self.stream.isatty() if colour is None else colour

    def __call__(self, a: Alert) -> None:
        if "silenced" in a.details or "inhibited_by" in a.details:
            return   # logged (JSON lines), not shown as new
        tag = f"{a.priority.upper():9}"
        if self.colour:
            tag = f"{COLOURS[a.priority]}{tag}{RESET}"
        self.stream.write(f"{hms(a.t)} {a.owner:>5} {tag} {a.type:16} {a.message}\n")


class JsonlSink:
    """One JSON object per alert per line; keys sorted so that replays are byte-identical.
    Flushed after every alert: a killed run loses no alert it has given."""

    def __init__(self, stream: IO[str]):
        self.stream = stream

    def __call__(self, a: Alert) -> None:
        self.stream.write(alert_line(a) + "\n")
        self.stream.flush()


class ListSink(list):
    def __call__(self, a: Alert) -> None:
        self.append(a)
