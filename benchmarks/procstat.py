"""What each process of a running mesh costs, sampled from /proc: CPU seconds, and peak
proportional set size (PSS: shared library pages split between the processes that map
them, what the machine really spends per process) beside peak RSS.

PSS splits a shared page between the processes that map it *now*: as a mesh's peers
exit at the end of a run, the last ones' PSS climbs (a brigade EA's from 44 to 58 MB
in the second its 56 siblings left) with no byte more spent. So `pss_mb` is the peak
taken while as many of the sampled processes ran as ever did (the whole mesh), and
`pss_mb_any` the peak at any moment, reported beside it."""
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
        self.most = 0   # the most sampled processes alive at once so far
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
        now = {name: s for name, pid in pids.items() if (s := sample(int(pid))) is not None}
        whole = len(now) >= self.most   # nobody has left since the mesh was at its fullest
        self.most = max(self.most, len(now))
        for name, s in now.items():
            p = self.peak.setdefault(name, {"cpu_s": 0.0, "pss_mb": 0.0, "pss_mb_any": 0.0, "rss_mb": 0.0})
            p["cpu_s"] = max(p["cpu_s"], s["cpu_s"])
            if whole:
                p["pss_mb"] = max(p["pss_mb"], s["pss_mb"])
            p["pss_mb_any"] = max(p["pss_mb_any"], s["pss_mb"])
            p["rss_mb"] = max(p["rss_mb"], s["rss_mb"])

    @property
    def peak_memory(self) -> dict[str, dict]:
        """Peak PSS (while the mesh was whole, and at any moment) and RSS per process name (MB, one decimal)."""
        return {n: {"pss_mb": round(p["pss_mb"], 1), "pss_mb_any": round(p["pss_mb_any"], 1),
                    "rss_mb": round(p["rss_mb"], 1)}
                for n, p in sorted(self.peak.items())}

    def report(self) -> dict[str, dict]:
        return {n: {k: round(v, 2) for k, v in p.items()} for n, p in sorted(self.peak.items())}
