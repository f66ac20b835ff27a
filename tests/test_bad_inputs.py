"""Every bad input gives one clear line on stderr and exit code 2: never a traceback,
a hang, or a silent acceptance. Most cases call `cli.main` in process; a few run the
real command line (every garbage endpoint among them)."""
import argparse
import gzip
import json
import os
import shutil
import subprocess
import sys

import pytest

from saim_mesh import cli
from saim_mesh import scenario as S
from saim_mesh.cli.args import _endpoint

from .conftest import ROOT, SMALL

# A few valid events of the small scenario (the bad one is appended after them).
LOC = '{"kind":"location","t":1,"entity":"A1S1E01","lon":-116.6,"lat":35.2}'
OK_EVENTS = [LOC, '{"kind":"mission","t":300,"mission":"A1-move","unit":"A1","phase":"start"}']


@pytest.fixture()
def scn(tmp_path):
    """A copy of scenarios/small to break (without truth.json, which loading does not read)."""
    d = tmp_path / "sc"
    d.mkdir()
    for f in ("scenario.json", "plan.json", "overlay.geojson", "events.jsonl.gz"):
        shutil.copy(SMALL / f, d / f)
    return d


def edit(path, fn):
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))


def events(*bad):
    """Replace the event script by a few good lines and `bad` (JSON strings or dicts)."""
    def mutate(d):
        (d / "events.jsonl.gz").unlink()
        lines = OK_EVENTS + [x if isinstance(x, str) else json.dumps(x) for x in bad]
        (d / "events.jsonl").write_text("\n".join(lines) + "\n")
    return mutate


def plan(fn):
    return lambda d: edit(d / "plan.json", fn)


def meta(fn):
    return lambda d: edit(d / "scenario.json", fn)


def overlay(fn):
    return lambda d: edit(d / "overlay.geojson", fn)


def unit(doc, uid):
    return next(u for u in doc["task_organization"] if u["id"] == uid)


def mission(doc, mid, plan_name="main"):
    return next(m for m in doc["plans"][plan_name] if m["id"] == mid)


def config(text):
    """A config case: `run DIR --ea A2 --quiet --config FILE` with this TOML."""
    def mutate(d):
        (d / "ea.toml").write_text(text)
        return ["run", str(d), "--ea", "A2", "--quiet", "--config", str(d / "ea.toml")]
    return mutate


def args(*extra):
    """A command-line case: `run DIR <extra>` on the intact scenario."""
    return lambda d: ["run", str(d), "--quiet", *extra]


# the mesh's processes with Zenoh options (issue 49.6): a garbage --connect or --listen is
# one line naming it, before any Zenoh session opens
COMMANDS = {
    "peer": lambda d: ["peer", "--scenario", str(d), "--unit", "A2", "--sources", "cp.A"],
    "source": lambda d: ["source", str(d), "--name", "cp.A"],
    "router": lambda d: ["router", "--scenario", str(d), "--name", "r"],
    "console": lambda d: ["console", str(d)],
}
BAD_ENDPOINTS = [("connect-garbage", "--connect", "garbage"), ("listen-notaport", "--listen", "tcp/127.0.0.1:notaport"),
                 ("connect-carrier-pigeon", "--connect", "carrier-pigeon/roof")]


def endpoint(cmd, opt, value):
    """A case: `cmd`'s command line (on the intact scenario) with `opt value`."""
    return lambda d: [*COMMANDS[cmd](d), opt, value]


def cycle_units(doc):
    unit(doc, "A")["parent"] = "A1"      # A -> A1 -> A, with BN still the one top unit


def cycle_after(doc):
    m1, m2 = doc["plans"]["main"][0], doc["plans"]["main"][1]
    m1["after"] = [m2["id"]]
    m2["after"] = [m1["id"]]


def rename_unit(doc, old, new):
    unit(doc, old)["id"] = new


def truncate_gzip(d):
    data = (d / "events.jsonl.gz").read_bytes()
    (d / "events.jsonl.gz").write_bytes(data[:len(data) // 2])


def corrupt_gzip(d):
    (d / "events.jsonl.gz").write_bytes(bytes(range(256)) * 64)


def invalid_utf8(d):
    events()(d)
    (d / "events.jsonl").write_bytes(b'{"kind": "\xff"}\n')


def nan_overlay(fc):
    fc["features"][0]["geometry"]["coordinates"][0][1] = [float("nan"), 35.0]


def lat_overlay(fc):
    fc["features"][0]["geometry"]["coordinates"][0][1][1] = 95.0


CASES = [
    # (id, mutate, expected substrings of the one stderr line)
    ("missing-plan", lambda d: (d / "plan.json").unlink(), ["plan.json", "file missing"]),
    ("missing-events", lambda d: (d / "events.jsonl.gz").unlink(), ["no events.jsonl"]),
    ("invalid-json", lambda d: (d / "plan.json").write_text('{"task_organization": ['), ["plan.json:1", "invalid JSON"]),
    ("meta-not-object", lambda d: (d / "scenario.json").write_text("[]"), ["scenario.json", "expected an object"]),
    ("negative-duration", meta(lambda m: m.update(duration_s=-5)), ["scenario.json", "field 'duration_s'", "> 0"]),
    ("nan-duration", meta(lambda m: m.update(duration_s=float("nan"))), ["field 'duration_s'", "finite"]),
    ("huge-duration", meta(lambda m: m.update(duration_s=1e300)), ["field 'duration_s'", "7 days"]),
    ("unknown-default-ea", meta(lambda m: m.update(default_eas=["BN", "Z9"])), ["field 'default_eas'", "Z9"]),
    ("fusion-group-hash", meta(lambda m: m.update(fusion={"groups": {"N#1": ["G1"]}})),
     ["scenario.json: fusion", "field 'name'", "'#'"]),
    ("fusion-sensor-nan-sigma", meta(lambda m: m.update(fusion={"groups": {"N": ["G1"]},
                                                                "sensors": [{"id": "G1", "sigma_m": float("nan")}]})),
     ["scenario.json: fusion.sensors[0] (G1)", "field 'sigma_m'", "finite number > 0"]),
    ("scenario-name-space", meta(lambda m: m.update(name="my scenario")), ["scenario.json", "field 'name'"]),
    ("nan-event-coordinate", events('{"kind":"location","t":400,"entity":"A1S1E01","lon":-116.6,"lat":NaN}'),
     ["events.jsonl:3", "field 'lat'", "finite"]),
    ("event-lon-out-of-range", events({"kind": "location", "t": 400, "entity": "A1S1E01", "lon": 200, "lat": 35.2}),
     ["events.jsonl:3", "field 'lon'"]),
    ("t-beyond-duration", events({"kind": "location", "t": 1e15, "entity": "A1S1E01", "lon": -116.6, "lat": 35.2}),
     ["events.jsonl:3", "field 't'", "after the end"]),
    ("t-1e300", events({"kind": "track", "t": 1e300, "track": "H1", "lon": -116.6, "lat": 35.2, "strength": 3}),
     ["events.jsonl:3", "field 't'", "duration_s"]),
    ("bool-for-int", events({"kind": "track", "t": 400, "track": "H1", "lon": -116.6, "lat": 35.2, "strength": True}),
     ["events.jsonl:3", "field 'strength'", "integer"]),
    ("track-id-dollar", events({"kind": "track", "t": 400, "track": "H$1", "lon": -116.6, "lat": 35.2, "strength": 3}),
     ["events.jsonl:3", "field 'track'", "'$'"]),
    ("entity-id-slash", events({"kind": "location", "t": 400, "entity": "X/1", "lon": -116.6, "lat": 35.2}),
     ["events.jsonl:3", "field 'entity'", "'/'"]),
    ("confirm-unknown-mission", events({"kind": "mission", "t": 400, "mission": "A1-fly", "unit": "A1", "phase": "end"}),
     ["events.jsonl:3", "field 'mission'", "A1-fly"]),
    ("confirm-wrong-unit", events({"kind": "mission", "t": 400, "mission": "A1-move", "unit": "A2", "phase": "end"}),
     ["events.jsonl:3", "field 'unit'", "A1-move"]),
    ("confirm-unknown-unit", events({"kind": "mission", "t": 400, "mission": "A1-move", "unit": "Z9", "phase": "end"}),
     ["events.jsonl:3", "field 'unit'", "unknown unit 'Z9'"]),
    ("order-unknown-plan", events({"kind": "order", "t": 400, "action": "execute-plan", "plan": "retreat", "issuer": "BN"}),
     ["events.jsonl:3", "field 'plan'", "retreat"]),
    ("order-unknown-issuer", events({"kind": "order", "t": 400, "action": "abort-plan", "plan": "main", "issuer": "Z9"}),
     ["events.jsonl:3", "field 'issuer'", "Z9"]),
    ("cff-unknown-requester", events({"kind": "cff", "t": 400, "cff": "F1", "requester": "Z9", "lon": -116.6,
                                      "lat": 35.2, "radius_m": 200}), ["events.jsonl:3", "field 'requester'"]),
    ("cff-id-space", events({"kind": "cff-confirm", "t": 400, "cff": "F 1", "requester": "A1", "lon": -116.6,
                             "lat": 35.2, "radius_m": 200}), ["events.jsonl:3", "field 'cff'"]),
    ("reorg-unknown-parent", events({"kind": "reorg", "t": 400, "unit": "A1", "new_parent": "Z9"}),
     ["events.jsonl:3", "field 'new_parent'", "Z9"]),
    ("hit-without-fusion", events({"kind": "hit", "t": 400, "sensor": "G1", "lon": -116.6, "lat": 35.2}),
     ["events.jsonl:3", "field 'sensor'", "fusion"]),
    ("alert-as-input", events({"kind": "alert", "t": 400, "owner": "A", "type": "contact", "category": "x",
                               "priority": "flash", "subjects": [], "message": "m"}), ["events.jsonl:3", "output"]),
    ("invalid-utf8", lambda d: invalid_utf8(d), ["events.jsonl", "UTF-8"]),
    ("truncated-gzip", truncate_gzip, ["events.jsonl.gz", "truncated or corrupt gzip"]),
    ("corrupt-gzip", corrupt_gzip, ["events.jsonl.gz", "truncated or corrupt gzip"]),
    ("after-cycle", plan(cycle_after), ["plan.json", "plans.main", "field 'after'", "cycle"]),
    ("after-itself", plan(lambda p: p["plans"]["main"][0].update(after=[p["plans"]["main"][0]["id"]])),
     ["plan.json", "field 'after'", "itself"]),
    ("unit-parent-cycle", plan(cycle_units), ["plan.json", "field 'parent'", "cycle", "A1"]),
    ("parent-not-string", plan(lambda p: unit(p, "A1").update(parent=["A"])), ["task_organization", "field 'parent'"]),
    ("duplicate-unit", plan(lambda p: unit(p, "A1S2").update(id="A1S1")), ["task_organization", "duplicate unit id"]),
    ("slash-in-unit-id", plan(lambda p: rename_unit(p, "A1S1", "A-CO/2-PLT")),
     ["plan.json: task_organization", "field 'id'", "'/'"]),
    ("star-in-mission-id", plan(lambda p: p["plans"]["main"][0].update(id="A1*move")),
     ["plan.json: plans.main[0]", "field 'id'", "'*'"]),
    ("question-in-plan-name", plan(lambda p: p["plans"].update({"with?drawal": p["plans"].pop("withdrawal")})),
     ["plan.json: plans", "field 'name'", "'?'"]),
    ("space-in-entity-id", plan(lambda p: unit(p, "A1S1")["entities"].__setitem__(0, "A1S1 E01")),
     ["task_organization", "field 'entities'", "whitespace"]),
    ("empty-mission-id", plan(lambda p: p["plans"]["main"][0].update(id="")), ["plans.main[0]", "field 'id'"]),
    ("weapons-range-string", plan(lambda p: unit(p, "BN").update(weapons_range_m="far")), ["field 'weapons_range_m'"]),
    ("mission-voi-unknown", plan(lambda p: mission(p, "A2-move")["params"].update(voi={"out_of_posn_m": 5})),
     ["plan.json", "A2-move", "params.voi.out_of_posn_m"]),
    ("mission-at-string", plan(lambda p: mission(p, "A3-linkup")["params"].update(at="soon")), ["field 'params.at'"]),
    ("reorg-unknown-parent-param", plan(lambda p: mission(p, "BN-reorg-R")["params"].update(new_parent="Z9")),
     ["BN-reorg-R", "field 'params.new_parent'", "Z9"]),
    ("nan-in-overlay", overlay(nan_overlay), ["overlay.geojson: feature 0", "field 'geometry'", "lon nan"]),
    ("lat-out-of-range-in-overlay", overlay(lat_overlay),
     ["overlay.geojson: feature 0", "field 'geometry'", "lat 95.0"]),
    ("overlay-width-string", overlay(lambda fc: fc["features"][2]["properties"].update(width_m="wide")),
     ["overlay.geojson: feature 2 (PL-BLUE-A)", "field 'width_m'", "expected a number"]),
    # nothing a user writes is silently ignored: parameters a mission class does not declare,
    # trigger keys its kind does not read, overlay properties the loader reads elsewhere or misspelt
    ("block-unknown-param", plan(lambda p: mission(p, "B1-defend")["params"].update(rear_line="PL-BLUE-B")),
     ["plan.json: plans.main[11] (B1-defend)", "field 'params.rear_line'", "unknown parameter of block",
      "block knows area, engagement_area, expect_hostile_by, fires, line, position, voi"]),
    ("move-param-typo", plan(lambda p: mission(p, "A1-move")["params"].update(routee=mission(p, "A1-move")
                                                                               ["params"].pop("route"))),
     ["(A1-move)", "field 'params.routee'", "unknown parameter of move", "did you mean 'route'?",
      "by, checkpoints, destination, fires, route, voi"]),
    ("required-param-typo", plan(lambda p: mission(p, "A1-attack")["params"].update(
        objectiv=mission(p, "A1-attack")["params"].pop("objective"))),
     ["(A1-attack)", "field 'params.objectiv'", "unknown parameter of attack", "did you mean 'objective'?"]),
    ("task-params-unknown", plan(lambda p: mission(p, "BN-branch-disrupt")["params"]["task_params"].update(
        engagement="EA-A")),
     ["(BN-branch-disrupt)", "field 'params.task_params.engagement'", "unknown parameter of disrupt",
      "did you mean 'engagement_area'?"]),
    ("trigger-key-of-other-kind", plan(lambda p: mission(p, "A-sequel-suppress")["params"]["trigger"].update(
        min_strength=2)),
     ["(A-sequel-suppress) params.trigger", "field 'min_strength'", "not read by a unit-at trigger",
      "kind, unit, area, within_m, rule"]),
    ("overlay-radius-on-polygon", overlay(lambda fc: fc["features"][3]["properties"].update(radius_m=300)),
     ["overlay.geojson: feature 3 (OBJ-A)", "field 'radius_m'", "not read for an objective Polygon",
      "id, kind, owner"]),
    ("overlay-radius-no-unit", overlay(lambda fc: fc["features"][45]["properties"].update(
        radius=fc["features"][45]["properties"].pop("radius_m"))),
     ["overlay.geojson: feature 45 (NAI-1)", "field 'radius'", "spelled like 'radius_m'",
      "id, kind, owner, radius_m"]),
    ("overlay-width-typo", overlay(lambda fc: fc["features"][49]["properties"].update(
        widht_m=fc["features"][49]["properties"].pop("width_m"))),
     ["overlay.geojson: feature 49 (AA-DIAMOND)", "field 'widht_m'", "spelled like 'width_m'"]),
    ("config-epoch-zero", config("[manager]\nepoch_s = 0\n"), ["ea.toml", "[manager]", "field 'epoch_s'", "> 0"]),
    ("config-fact-batch-string", config("[manager]\nfact_batch = \"x\"\n"), ["ea.toml", "field 'fact_batch'", "integer"]),
    ("config-fact-batch-negative", config("[manager]\nfact_batch = -3\n"), ["field 'fact_batch'", "> 0"]),
    ("config-reregister-zero", config("[dissemination]\nreregister_s = 0.0\n"), ["field 'reregister_s'"]),
    ("config-scan-bool", config("[manager]\nunknown_scan_s = true\n"), ["field 'unknown_scan_s'", "boolean"]),
    ("config-voi-number", config("voi = 5\n"), ["ea.toml", "field 'voi'", "table"]),
    ("config-per-ea", config("[ea.A2.voi]\nout_of_position_m = -1.0\n"), ["[ea.A2.voi]", "field 'out_of_position_m'"]),
    ("config-unknown-key", config("[manager]\nepoch = 2.0\n"), ["ea.toml", "field 'epoch'", "unknown key"]),
    ("config-invalid-toml", config("[manager\n"), ["ea.toml", "invalid TOML"]),
    ("config-missing", lambda d: ["run", str(d), "--ea", "A2", "--config", str(d / "nope.toml")], ["nope.toml"]),
    ("unknown-ea", args("--ea", "Z9"), ["--ea", "Z9", "unknown unit"]),
    ("speed-negative", args("--speed", "-1"), ["--speed", "> 0"]),
    ("out-unwritable", lambda d: ["run", str(d), "--ea", "A2", "--quiet", "--out", str(d / "no" / "a.jsonl")],
     ["a.jsonl", "No such file"]),
    ("not-a-folder", lambda d: ["validate", str(d / "nothing")], ["nothing", "not a scenario folder"]),
    ("mesh-restarts-negative", lambda d: ["mesh", "up", str(d), "--restarts", "-1"],
     ["saim-mesh mesh", "--restarts", "whole number >= 0", "'-1'"]),
    ("mesh-restarts-garbage", lambda d: ["mesh", "up", str(d), "--restarts", "garbage"],
     ["saim-mesh mesh", "--restarts", "whole number >= 0", "'garbage'"]),
    ("deploy-restarts-negative", lambda d: ["deploy", str(d / "deploy.toml"), "--restarts", "-2"],
     ["saim-mesh deploy", "--restarts", "'-2'"]),
    *((f"{cmd}-{case}", endpoint(cmd, opt, value), [f"saim-mesh {cmd}", opt, value[:20]])
      for cmd in sorted(COMMANDS) for case, opt, value in BAD_ENDPOINTS),
]
ENDPOINT_CASES = [f"{cmd}-{case}" for cmd in sorted(COMMANDS) for case, _, _ in BAD_ENDPOINTS]


def one_error_line(err: str) -> str:
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("mutate, expect", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_gives_one_line_and_exit_2(scn, capsys, mutate, expect):
    argv = mutate(scn)
    if not isinstance(argv, list):   # a broken scenario: validate it
        argv = ["validate", str(scn)]
    capsys.readouterr()
    try:
        rc = cli.main(argv)
    except SystemExit as e:   # argparse
        rc = e.code
    out = capsys.readouterr()
    assert rc == 2, out
    line = one_error_line(out.err)
    for part in expect:
        assert part in line, line


def run_cli(*argv):
    env = {**os.environ}
    env.pop("SAIM_MESH_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "saim_mesh", *argv], capture_output=True, text=True, cwd=ROOT,
                          timeout=60, env=env)


@pytest.mark.timeout(120)
@pytest.mark.parametrize("case", ["truncated-gzip", "config-epoch-zero", "nan-in-overlay", "mesh-restarts-negative",
                                  *ENDPOINT_CASES])
def test_real_command_line(scn, case):
    mutate, expect = next(c[1:] for c in CASES if c[0] == case)
    argv = mutate(scn)
    r = run_cli(*(argv if isinstance(argv, list) else ["validate", str(scn)]))
    assert r.returncode == 2, r
    line = one_error_line(r.stderr)
    for part in expect:
        assert part in line, line


@pytest.mark.parametrize("ep", ["tcp/127.0.0.1:7447", "tls/localhost:0", "udp/198.18.0.1:7447",
                                "tcp/[::1]:7447", "unixsock-stream//tmp/z.sock", "tcp/127.0.0.1:7447#iface=lo"])
def test_a_good_endpoint_is_taken_as_given(ep):
    assert _endpoint(ep) == ep


@pytest.mark.parametrize("ep", ["", "tcp/", "tcp/127.0.0.1", "tcp/:7447", "tcp/h:99999", "127.0.0.1:7447"])
def test_a_bad_endpoint_is_refused(ep):
    with pytest.raises(argparse.ArgumentTypeError):
        _endpoint(ep)


def test_good_scenario_still_validates(capsys):
    assert cli.main(["validate", str(SMALL)]) == 0
    out = capsys.readouterr()
    assert out.out.strip().endswith("OK") and not out.err


def test_copy_validates(scn):
    """The fixture and the short event script are good: each case fails because of its one change."""
    assert cli.main(["validate", str(scn)]) == 0
    events()(scn)
    assert cli.main(["validate", str(scn)]) == 0


def test_descriptive_properties_still_validate(scn):
    """Overlay properties the loader does not read are the user's own description (the
    console shows them): a name, a note, a GIS tool's fid or styling are no error."""
    def describe(fc):
        for f in fc["features"]:
            f["properties"].update(name=f"the {f['properties']['id']}", description="from the OPORD", fid=7,
                                   stroke="#ff0000")
    overlay(describe)(scn)
    assert cli.main(["validate", str(scn)]) == 0


def test_every_declared_param_is_known():
    """A class knows what it and its ancestors declare (PARAMS, merged): the loader's list of
    a class's parameters is the one `saim-mesh missions` prints."""
    from ea_agent.domains.suo.missions import REGISTRY
    for typ, cls in REGISTRY.items():
        assert set(cls.required()) <= set(cls.all_params()), typ
        assert {*cls.GEOMETRY_PARAMS, *cls.UNIT_PARAMS} <= set(cls.all_params()), typ
        assert cls.unknown_params({p: None for p in cls.all_params()}) == [], typ
    assert REGISTRY["block"].unknown_params({"position": "BP", "rear_line": "PL"}) == ["rear_line"]


def test_key_chunk_helper():
    assert S.check_key_chunk("A1S1E01", "w", "id") == "A1S1E01"
    for bad in ("", "a/b", "a*", "#", "a?", "$x", "a b", "a\tb", None, 3):
        with pytest.raises(S.ScenarioError, match="field 'id'"):
            S.check_key_chunk(bad, "w", "id")


def test_cycles_never_hang():
    from ea_agent.core.plan import MissionSpec, PlanSpec, TaskOrg, Unit
    to = TaskOrg([Unit("BN", "", "battalion", None), Unit("A", "", "company", "B"), Unit("B", "", "company", "A")])
    assert to.cycle() in (["A", "B", "A"], ["B", "A", "B"])
    with pytest.raises(ValueError):
        to.ancestors("A")
    with pytest.raises(ValueError):
        to.subtree("A")
    ok = PlanSpec("p", [MissionSpec("a", "A", "move"), MissionSpec("b", "A", "move", after=("a",))])
    assert ok.cycle() is None
    bad = PlanSpec("p", [MissionSpec("a", "A", "move", after=("c",)), MissionSpec("b", "A", "move", after=("a",)),
                         MissionSpec("c", "A", "move", after=("b",))])
    assert bad.cycle() is not None and len(bad.cycle()) == 4


def test_jsonl_sink_flushes_every_alert(tmp_path):
    from saim_mesh.protocol.messages import Alert
    from saim_mesh.logs.sinks import JsonlSink
    p = tmp_path / "a.jsonl"
    with open(p, "w") as f:   # block-buffered: only the sink's flush puts the line in the file
        JsonlSink(f)(Alert(1.0, "A", "contact", "c", "flash", ("A1",), "m"))
        assert p.read_text().count("\n") == 1


def test_gzip_round_trip_still_loads(scn):
    with gzip.open(scn / "events.jsonl.gz", "rt") as f:
        n = sum(1 for line in f if line.strip())
    assert len(S.load(scn).events) == n
