"""The sampler's PSS peak is taken while the whole mesh runs: once processes leave, the
survivors' PSS rises (shared pages split among fewer) and only `pss_mb_any` shows it."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from benchmarks import procstat


def _sleeper() -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)


@pytest.mark.timeout(60)
def test_pss_peaks_stop_once_a_process_has_left(tmp_path, monkeypatch):
    a, b = _sleeper(), _sleeper()
    try:
        pids = tmp_path / "pids.json"
        pids.write_text(json.dumps({"a": a.pid, "b": b.pid}))
        smp = procstat.Sampler(pids)
        real = procstat.sample
        bump = {"pss": 0.0}
        monkeypatch.setattr(procstat, "sample", lambda pid: None if (s := real(pid)) is None else
                            {**s, "pss_mb": s["pss_mb"] + bump["pss"]})
        smp.once()
        whole = smp.peak["a"]["pss_mb"]
        assert whole > 0 and smp.most == 2
        b.stdin.close()
        b.wait(10)
        bump["pss"] = 100.0   # what a survivor's PSS does when its siblings go
        smp.once()
        assert smp.peak["a"]["pss_mb"] == whole            # not the whole mesh any more: not counted
        assert smp.peak["a"]["pss_mb_any"] >= whole + 100.0  # but reported beside it
        assert smp.peak_memory["a"]["pss_mb_any"] >= 100.0
    finally:
        for p in (a, b):
            if p.poll() is None:
                p.stdin.close()
                p.wait(10)


def test_a_process_starting_later_still_counts(tmp_path):
    a = _sleeper()
    b = None
    try:
        pids = tmp_path / "pids.json"
        pids.write_text(json.dumps({"a": a.pid}))
        smp = procstat.Sampler(pids)
        smp.once()
        b = _sleeper()
        pids.write_text(json.dumps({"a": a.pid, "b": b.pid}))
        smp.once()
        assert smp.most == 2 and smp.peak["b"]["pss_mb"] > 0   # the mesh growing is the mesh whole
    finally:
        for p in (a, b):
            if p is not None and p.poll() is None:
                p.stdin.close()
                p.wait(10)
