"""What a process really costs in memory: proportional set size (shared pages split
among the processes that map them) beside resident set size, from
/proc/PID/smaps_rollup, sampled while a mesh runs."""
from __future__ import annotations

import json
import threading
from pathlib import Path


def pss_rss_mb(pid: int) -> tuple[float, float] | None:
    """(PSS, RSS) in MB of a live process, None when it is gone or unreadable."""
    try:
        text = Path(f"/proc/{pid}/smaps_rollup").read_text()
    except OSError:
        return None
    kb = {}
    for line in text.splitlines():
        name, _, rest = line.partition(":")
        if name in ("Pss", "Rss"):
            kb[name] = int(rest.split()[0])
    if len(kb) < 2:
        return None
    return kb["Pss"] / 1024.0, kb["Rss"] / 1024.0


class Sampler:
    """Peak PSS and RSS per process name, read every `every_s` from a pids file
    (`{name: pid}`, written by mesh.Supervisor) until stopped."""

    def __init__(self, pids_path: Path, every_s: float = 0.25, extra=None):
        self.pids_path, self.every_s = Path(pids_path), every_s
        self.extra = extra or (lambda: {})   # () -> {name: pid} of processes not in the file (a zygote)
        self.peak: dict[str, dict[str, float]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pss-sampler", daemon=True)

    def __enter__(self) -> "Sampler":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(5.0)

    def _run(self) -> None:
        while not self._stop.wait(self.every_s):
            try:
                pids = {**json.loads(self.pids_path.read_text()), **self.extra()}
            except (OSError, ValueError):
                continue
            for name, pid in pids.items():
                m = pss_rss_mb(int(pid))
                if m is None:
                    continue
                p = self.peak.setdefault(name, {"pss_mb": 0.0, "rss_mb": 0.0})
                p["pss_mb"] = round(max(p["pss_mb"], m[0]), 1)
                p["rss_mb"] = round(max(p["rss_mb"], m[1]), 1)
