"""What each process of a running mesh costs, sampled from /proc: CPU seconds, and peak
proportional set size (PSS: shared library pages split between the processes that map
them, what the machine really spends per process) beside peak RSS."""
from __future__ import annotations

import json
import os
import threading
from pathlib import Path

_TICK = os.sysconf("SC_CLK_TCK")


def sample(pid: int) -> dict | None:
    """{'cpu_s', 'pss_mb', 'rss_mb'} of one live process, or None when it is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        rollup = Path(f"/proc/{pid}/smaps_rollup").read_text()
    except (OSError, ValueError):
        return None
    fields = stat[stat.rindex(")") + 2:].split()
    cpu = (int(fields[11]) + int(fields[12])) / _TICK   # utime + stime
    kb = {line.split(":")[0]: int(line.split()[1]) for line in rollup.splitlines()[1:] if line.split()[-1] == "kB"}
    return {"cpu_s": cpu, "pss_mb": kb.get("Pss", 0) / 1024, "rss_mb": kb.get("Rss", 0) / 1024}


class Sampler:
    """Samples every process named in a mesh's pids.json (restarts pick up new pids)
    every `every_s` until stopped; keeps per name the peak PSS/RSS and the last CPU."""

    def __init__(self, pids_path: Path, every_s: float = 1.0, extra=None):
        self.pids_path, self.every_s = Path(pids_path), every_s
        self.extra = extra or (lambda: {})   # () -> {name: pid} of processes not in the file (a zygote)
        self.peak: dict[str, dict] = {}
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> "Sampler":
        self._t.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._t.join(10)

    def _run(self) -> None:
        while not self._stop.wait(self.every_s):
            self.once()

    def once(self) -> None:
        try:
            pids = {**json.loads(self.pids_path.read_text()), **self.extra()}
        except (OSError, ValueError):
            return
        for name, pid in pids.items():
            s = sample(int(pid))
            if s is None:
                continue
            p = self.peak.setdefault(name, {"cpu_s": 0.0, "pss_mb": 0.0, "rss_mb": 0.0})
            p["cpu_s"] = max(p["cpu_s"], s["cpu_s"])
            p["pss_mb"] = max(p["pss_mb"], s["pss_mb"])
            p["rss_mb"] = max(p["rss_mb"], s["rss_mb"])

    @property
    def peak_memory(self) -> dict[str, dict]:
        """Peak PSS and RSS per process name (MB, one decimal)."""
        return {n: {"pss_mb": round(p["pss_mb"], 1), "rss_mb": round(p["rss_mb"], 1)}
                for n, p in sorted(self.peak.items())}

    def report(self) -> dict[str, dict]:
        return {n: {k: round(v, 2) for k, v in p.items()} for n, p in sorted(self.peak.items())}
