import json
import subprocess
import sys

from .conftest import ROOT, SMALL

KEYS = {"t", "owner", "type", "category", "priority", "subjects", "message", "details"}


def cli(*args, check=True):
    return subprocess.run([sys.executable, "-m", "saim_mesh", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=300, check=check)


def test_missions_lists_the_model():
    out = cli("missions").stdout
    names = [line.split()[0] for line in out.splitlines() if not line.startswith(" ")]
    assert len(names) >= 25
    for n in ("move", "attack", "attack-by-fire", "support-by-fire", "defend", "screen", "observe", "seize",
              "clear", "block", "reorganize", "branch", "link-up"):
        assert n in names
    assert "destination" in out and "objective" in out


def test_run_writes_alert_lines_and_the_table(tmp_path):
    f = tmp_path / "alerts.jsonl"
    r = cli("run", str(SMALL), "--ea", "BN", "A2", "--speed", "max", "--out", str(f))
    lines = [json.loads(x) for x in f.read_text().splitlines()]
    assert lines and all(KEYS <= set(x) for x in lines)
    assert {x["owner"] for x in lines} == {"BN", "A2"}
    assert "fratricide" in r.stdout and "total" in r.stdout and "FLASH" in r.stdout


def test_unknown_unit_and_broken_scenario_fail_clearly(tmp_path):
    r = cli("run", str(SMALL), "--ea", "Z9", "--quiet", check=False)
    assert r.returncode == 2 and "Z9" in r.stderr
    r = cli("validate", str(tmp_path), check=False)
    assert r.returncode == 2 and "scenario.json" in r.stderr


UV = ROOT / "scenarios" / "uv-team"


def test_the_robot_domain_from_the_command_line(tmp_path):
    f = tmp_path / "uv.jsonl"
    r = cli("run", str(UV), "--speed", "max", "--out", str(f), "--quiet")
    lines = [json.loads(x) for x in f.read_text().splitlines()]
    assert {x["owner"] for x in lines} >= {"TEAM", "UGV1", "UAV2"}
    assert "no-status" in r.stdout and "target-visible" in r.stdout   # the table's rows are the UV types
    out = cli("missions", "--domain", "uv").stdout
    assert {line.split()[0] for line in out.splitlines() if not line.startswith(" ")} >= {
        "goto", "patrol", "search", "pursue", "photograph"}
    assert cli("validate", str(UV)).stdout.rstrip().endswith("OK")
    cli("generate", str(tmp_path / "gen"), "--domain", "uv")
    assert (tmp_path / "gen" / "events.jsonl.gz").read_bytes() == (UV / "events.jsonl.gz").read_bytes()


def test_a_scenario_of_an_unknown_domain_fails_clearly(tmp_path):
    (tmp_path / "scenario.json").write_text('{"domain": "submarines", "epsg": 32611, "duration_s": 10}')
    r = cli("validate", str(tmp_path), check=False)
    assert r.returncode == 2 and "submarines" in r.stderr and "scenario.json" in r.stderr
