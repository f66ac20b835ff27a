"""The quality targets on ground truth (recall, unwanted share, flash, reduction vs naive)."""
import json
import subprocess
import sys

from saim_mesh import scenario as S
from saim_mesh.evaluate import evaluate

from .conftest import BATTALION, ROOT, SMALL


def check(res):
    assert res["recall"] == 1.0, res["missed"]
    assert res["unwanted_share"] <= 0.05, res["unwanted_alerts"]
    assert res["unwanted_flash"] == 0
    assert res["naive_alerts"] >= 50 * res["alerts"]


def test_small_scenario_meets_targets():
    check(evaluate(S.load(SMALL)))


def test_battalion_meets_targets_via_cli():
    out = subprocess.run([sys.executable, "-m", "saim_mesh", "evaluate", str(BATTALION), "--json"],
                         capture_output=True, text=True, cwd=ROOT, timeout=600, check=True)
    res = json.loads(out.stdout)
    for k in ("recall", "unwanted_share", "unwanted_flash", "alerts", "naive_alerts"):
        assert k in res
    check(res)
