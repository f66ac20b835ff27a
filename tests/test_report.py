"""`saim-mesh report`: a PNG of alert counts and a timeline, from a run's alert files."""
import json
import subprocess
import sys

import pytest

from saim_mesh.inprocess.report import ReportError, plot, read_alerts

from .conftest import ROOT, SMALL


def test_report_of_a_run_is_a_png_with_every_alert_counted(tmp_path):
    alerts = tmp_path / "alerts.jsonl"
    subprocess.run([sys.executable, "-m", "saim_mesh", "run", str(SMALL), "--ea", "BN", "A2", "--speed", "max",
                    "--quiet", "--out", str(alerts)], cwd=ROOT, check=True, capture_output=True, timeout=300)
    lines = [json.loads(x) for x in alerts.read_text().splitlines()]
    out = tmp_path / "report.png"
    r = subprocess.run([sys.executable, "-m", "saim_mesh", "report", str(out), str(alerts)], cwd=ROOT,
                       check=True, capture_output=True, text=True, timeout=120)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
    assert f"{len(lines)} alerts of 2 EAs" in r.stdout
    counts = plot(read_alerts([alerts]), tmp_path / "again.png")
    assert sum(counts["A2"].values()) == sum(1 for a in lines if a["owner"] == "A2")


@pytest.mark.parametrize("text, why", [("{bad json", "invalid JSON"), ('{"t": 1}', "not an alert"),
                                       ("", "no alerts")])
def test_bad_alert_files_are_named(tmp_path, text, why):
    f = tmp_path / "a.jsonl"
    f.write_text(text)
    with pytest.raises(ReportError, match=why):
        read_alerts([f])
