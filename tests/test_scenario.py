import gzip
import json
import shutil

import pytest

from saim_mesh import scenario as S
from ea_agent.domains.suo.generator import write

from .conftest import BATTALION, SMALL


def test_battalion_is_big_enough():
    sc = S.load(BATTALION)
    assert len(sc.taskorg.entity_unit) >= 400
    assert len(sc.events) >= 45_000
    assert sc.duration_s >= 5400
    echelons = [u.kind for u in sc.taskorg.units.values()]
    assert echelons.count("company") >= 3 and "squad" in echelons and "platoon" in echelons
    assert {type(e).__name__ for e in sc.events} >= {"LocationReport", "SensorTrack", "MissionConfirm",
                                                      "CallForFire", "CallForFireConfirm"}


def test_generator_is_deterministic(tmp_path):
    write(tmp_path / "s", small=True)
    for f in ("plan.json", "overlay.geojson", "events.jsonl.gz", "truth.json"):
        assert (tmp_path / "s" / f).read_bytes() == (SMALL / f).read_bytes(), f


@pytest.fixture()
def broken(tmp_path):
    d = tmp_path / "sc"
    shutil.copytree(SMALL, d)
    return d


def _edit_json(path, fn):
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))


def _events(d, lines):
    (d / "events.jsonl.gz").unlink()
    (d / "events.jsonl").write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("mutate, expect", [
    (lambda d: _edit_json(d / "plan.json", lambda p: p["plans"]["main"][0].update(type="mvoe")),
     ["plan.json", "plans.main[0]", "field 'type'", "mvoe"]),
    (lambda d: _edit_json(d / "plan.json", lambda p: p["plans"]["main"][0].update(unit="Z9")),
     ["plan.json", "field 'unit'", "Z9"]),
    (lambda d: _edit_json(d / "plan.json", lambda p: p["plans"]["main"][0]["params"].pop("destination")),
     ["plan.json", "params.destination", "missing"]),
    (lambda d: _edit_json(d / "plan.json", lambda p: p["plans"]["main"][0]["start"].update(type="START-SOON")),
     ["plan.json", "field 'type'", "START-SOON"]),
    (lambda d: _edit_json(d / "overlay.geojson", lambda f: f["features"][3]["properties"].update(kind="castle")),
     ["overlay.geojson", "feature 3", "field 'kind'", "castle"]),
    (lambda d: _edit_json(d / "overlay.geojson", lambda f: f["features"][2]["geometry"].update(
        coordinates=[[[0, 0], [1, 0], [1, 400], [0, 0]]])),
     ["overlay.geojson", "feature 2", "field 'geometry'"]),
    (lambda d: _events(d, ['{"kind":"location","t":1,"entity":"A1S1E01","lon":-116.6,"lat":35.2}',
                           '{"kind":"location","t":2,"entity":"A1S1E01","lon":-116.6,"lat":NaN}']),
     ["events.jsonl:2", "lat"]),
    (lambda d: _events(d, ['{"kind":"location","t":5,"entity":"A1S1E01","lon":-116.6,"lat":35.2}',
                           '{"kind":"location","t":2,"entity":"A1S1E01","lon":-116.6,"lat":35.2}']),
     ["events.jsonl:2", "field 't'", "time-ordered"]),
    (lambda d: _events(d, ['{"kind":"location","t":1,"entity":"A1S1E01","lon":-116.6']),
     ["events.jsonl:1", "invalid JSON"]),
    (lambda d: (d / "plan.json").write_text("{not json"), ["plan.json:1", "invalid JSON"]),
])
def test_broken_scenario_names_file_place_and_field(broken, mutate, expect):
    mutate(broken)
    with pytest.raises(S.ScenarioError) as e:
        S.load(broken)
    for part in expect:
        assert part in str(e.value)


def test_events_plain_or_gzip_load_the_same(broken):
    with gzip.open(broken / "events.jsonl.gz", "rt") as f:
        text = f.read()
    a = S.load(broken).events
    (broken / "events.jsonl.gz").unlink()
    (broken / "events.jsonl").write_text(text)
    assert S.load(broken).events == a
