"""`saim-mesh report OUT.png ALERTS...`: a picture for an after-action report from a
run's alert files (JSON lines, as `run --out` and the mesh peers write them): alert
counts by type per EA (the paper's Fig. 7) and a timeline of alerts by priority."""
from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")   # no display: files only
import matplotlib.pyplot as plt  # noqa: E402

from ea_agent.core.alert import PRIORITIES, hms  # noqa: E402

COLOURS = {"flash": "#d62728", "immediate": "#ff7f0e", "priority": "#1f77b4", "routine": "#7f7f7f"}


class ReportError(ValueError):
    pass


def read_alerts(paths: list[Path]) -> list[dict]:
    """Every alert line of the files; a bad line is an error naming file and line."""
    out = []
    for p in paths:
        try:
            lines = Path(p).read_text().splitlines()
        except OSError as e:
            raise ReportError(f"{p}: cannot read: {e.strerror or e}") from None
        for i, line in enumerate(lines, 1):
            if not line.strip():
                continue
            try:
                a = json.loads(line)
            except json.JSONDecodeError as e:
                raise ReportError(f"{p}:{i}: invalid JSON: {e.msg}") from None
            if not isinstance(a, dict) or not {"t", "owner", "type", "priority"} <= set(a):
                raise ReportError(f"{p}:{i}: not an alert (needs t, owner, type, priority)")
            if a["priority"] not in PRIORITIES or not isinstance(a["t"], (int, float)):
                raise ReportError(f"{p}:{i}: field 'priority' or 't' is not an alert's")
            out.append(a)
    if not out:
        raise ReportError("no alerts in " + ", ".join(str(p) for p in paths))
    return out


def plot(alerts: list[dict], out: Path, title: str = "") -> dict:
    """Write the PNG; returns the counts drawn (for tests and logs)."""
    owners = sorted({a["owner"] for a in alerts})
    types = sorted({a["type"] for a in alerts})
    counts = {o: Counter(a["type"] for a in alerts if a["owner"] == o) for o in owners}
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(11, 8.5), gridspec_kw={"height_ratios": [3, 2]})
    width = 0.8 / max(1, len(owners))
    for k, o in enumerate(owners):
        xs = [i + k * width for i in range(len(types))]
        ax1.bar(xs, [counts[o][t] for t in types], width, label=o)
    ax1.set_xticks([i + 0.4 - width / 2 for i in range(len(types))], types, rotation=30, ha="right")
    ax1.set_ylabel("alerts")
    ax1.set_title(title or "Alerts by type per EA (cf. Fig. 7)")
    ax1.legend(ncol=min(6, len(owners)), fontsize=8)
    for p in PRIORITIES:
        ts = [a["t"] for a in alerts if a["priority"] == p]
        if ts:
            ax2.scatter(ts, [PRIORITIES.index(p)] * len(ts), s=12, color=COLOURS[p], label=f"{p} ({len(ts)})")
    ax2.set_yticks(range(len(PRIORITIES)), PRIORITIES)
    ax2.invert_yaxis()
    ticks = ax2.get_xticks()
    ax2.set_xticks(ticks, [hms(max(0.0, t)) for t in ticks], fontsize=8)
    ax2.set_xlabel("scenario time")
    ax2.set_title("Timeline of alerts by priority")
    ax2.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return {o: dict(c) for o, c in counts.items()}


def main_report(out: str, inputs: list[str], title: str = "") -> int:
    paths: list[Path] = []
    for i in inputs:   # a folder means every *.jsonl in it (a mesh's out dir)
        p = Path(i)
        paths += sorted(p.glob("*.jsonl")) if p.is_dir() else [p]
    counts = plot(read_alerts(paths), Path(out), title)
    print(f"{out}: {sum(sum(c.values()) for c in counts.values())} alerts of {len(counts)} EAs")
    return 0
