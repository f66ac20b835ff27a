"""A peer's commands as a JSON-lines log, and reading it back for a replay.

Why: acknowledgements, silences, thresholds and confirmations change what an EA
raises, and they arrive on the wall clock. The peer applies each one after a clock
tick and writes down that tick's scenario time; `saim-mesh run --commands FILE`
applies the same commands after the same tick, so a run with a commander in the
loop replays to the same alerts.

One line per command the EA took (decoded and applied, good or refused by the EA):
`{"unit", "t", "kind", "cmd": {...the struct's fields}, "ok", "error"}`.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import msgspec

from ..protocol import wire as W

SUFFIX = ".cmdlog"


def path_for(alerts_path: str | Path) -> Path:
    """Beside the peer's alert log: A2.jsonl -> A2.cmdlog (not *.jsonl: reports read those)."""
    p = Path(alerts_path)
    return p.with_suffix(SUFFIX)


class CommandLog:
    """Append-only; each line flushed and fsynced (commands are rare, each one matters)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.f = open(self.path, "a", encoding="utf-8")

    def write(self, unit: str, t: float, cmd: msgspec.Struct, res: W.CmdResult, after: bool = False) -> None:
        kind = next(k for k, c in W.COMMANDS.items() if c is type(cmd))
        line = {"unit": unit, "t": t, "kind": kind, "cmd": msgspec.to_builtins(cmd), "ok": res.ok,
                "error": res.error}
        if after:   # taken after every fact at t (a live peer): `run --commands` does the same
            line["after"] = True
        self.f.write(json.dumps(line, sort_keys=True) + "\n")
        self.f.flush()
        os.fsync(self.f.fileno())

    def directive(self, unit: str, tk, res: W.CmdResult) -> None:
        """A directive the EA took or refused (saim_mesh/authority/directives.py): kind `dir.<kind>`,
        with its issuer `by`; `run --commands` applies it again the same way."""
        line = {"unit": unit, "t": tk.t, "kind": f"dir.{res.kind}", "by": tk.by, "cmd": msgspec.to_builtins(tk.d),
                "ok": res.ok, "error": res.error}
        self.f.write(json.dumps(line, sort_keys=True) + "\n")
        self.f.flush()
        os.fsync(self.f.fileno())

    def close(self) -> None:
        self.f.close()


@dataclass(frozen=True, slots=True)
class Logged:
    """`after`: the EA took it after every fact at `t` (a live peer, which advances as far
    as its sources promised, facts at `t` included); else before the facts at `t` (a
    replay-driven peer, after a tick that promises only what is before `t`)."""
    unit: str
    t: float
    cmd: msgspec.Struct
    after: bool = False


def read(paths: list[str | Path], units: set[str] | None = None) -> list[Logged]:
    """Every command in the logs, in scenario-time order (stable within a file). A bad
    line raises ValueError naming the file, the line and what was wrong."""
    out: list[tuple[float, int, Logged]] = []
    n = 0
    for path in paths:
        try:
            lines = Path(path).read_text(encoding="utf-8").splitlines()
        except OSError as e:
            raise ValueError(f"{path}: cannot read the command log ({e.strerror or e})") from None
        for i, raw in enumerate(lines, 1):
            if not raw.strip():
                continue
            where = f"{path} line {i}"
            try:
                d = json.loads(raw)
            except json.JSONDecodeError as e:
                if i == len(lines):   # a half-written last line (killed mid-write): the command never took
                    continue
                raise ValueError(f"{where}: not JSON ({e.msg})") from None
            if not isinstance(d, dict):
                raise ValueError(f"{where}: not an object")
            unit, t, kind = d.get("unit"), d.get("t"), d.get("kind")
            if not isinstance(unit, str) or not unit:
                raise ValueError(f"{where}: unit missing")
            if units is not None and unit not in units:
                raise ValueError(f"{where}: unknown unit {unit!r}")
            if type(t) not in (int, float) or not math.isfinite(t) or not 0 <= t <= W.T_LIMIT:
                raise ValueError(f"{where}: t must be a scenario time in seconds (got {t!r})")
            if isinstance(kind, str) and kind.startswith("dir."):   # a directive (saim_mesh/authority/directives.py)
                from ..authority import directives as D
                by = d.get("by")
                if not isinstance(by, str) or not by:
                    raise ValueError(f"{where}: a directive with no issuer ('by')")
                try:
                    cls = D.TYPES.get(kind[4:])
                    if cls is None:
                        raise ValueError(f"unknown directive kind {kind[4:]!r}")
                    body = msgspec.msgpack.encode(msgspec.convert(d.get("cmd"), cls))   # JSON: bytes in base64
                    tk = D.Taken(by, D.decode(kind[4:], body, 1 << 17))
                except Exception as e:
                    raise ValueError(f"{where}: bad directive: {getattr(e, 'problem', e)}") from None
                n += 1
                out.append((float(t), n, Logged(unit, float(t), tk)))
                continue
            cls = W.COMMANDS.get(kind) if isinstance(kind, str) else None
            if cls is None:
                raise ValueError(f"{where}: unknown command kind {kind!r} (one of {', '.join(W.COMMANDS)})")
            try:
                cmd = msgspec.convert(d.get("cmd"), cls)
            except msgspec.ValidationError as e:
                raise ValueError(f"{where}: bad {kind} command: {e}") from None
            n += 1
            after = d.get("after", False)
            if not isinstance(after, bool):
                raise ValueError(f"{where}: 'after' must be true or false (got {after!r})")
            out.append((float(t), n, Logged(unit, float(t), cmd, after)))
    out.sort(key=lambda x: (x[0], x[1]))
    return [x[2] for x in out]
