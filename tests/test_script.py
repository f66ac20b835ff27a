"""The replay's compact script (`saim_mesh/script.py`) reads like the list of
`(event, key, payload, source)` it replaced, shares repeated keys, and the replay's
own script round-trips every payload to its event."""
from __future__ import annotations

from pathlib import Path

import pytest

from saim_mesh import messages as M
from saim_mesh import scenario as S
from saim_mesh.replay import Replay
from saim_mesh.script import Script

SMALL = Path(__file__).resolve().parents[1] / "scenarios" / "small"


def _entries():
    # keys built apart, so that equal keys are distinct objects going in
    return [(f"ev{i}", "".join(["k/", str(i % 3)]), bytes([i]) * (i % 4), "src" + str(i % 2)) for i in range(10)]


def test_a_script_reads_like_the_list_it_replaces():
    want = _entries()
    s = Script()
    for e in want:
        s.append(*e)
    s.close()
    assert len(s) == len(want)
    assert list(s) == want
    assert [s[i] for i in range(len(want))] == want
    assert s[-1] == want[-1]
    assert s[2:7] == want[2:7] and s[:0] == [] and s[8:] == want[8:] and s[::3] == want[::3] and s[::-1] == want[::-1]
    assert list(s.since(4)) == want[4:] and list(s.since(3, 6)) == want[3:6] and list(s.since(10)) == []
    assert s.payload(0) == b"" and s.payload(3) == bytes([3]) * 3
    with pytest.raises(IndexError):
        s[len(want)]


def test_repeated_keys_and_sources_are_one_string_each_and_a_closed_script_takes_nothing():
    s = Script()
    for e in _entries():
        s.append(*e)
    assert s.keys[0] is s.keys[3] is s.keys[9] and s.sources[1] is s.sources[3]
    s.close()
    with pytest.raises(ValueError, match="closed"):
        s.append("x", "k/0", b"", "src0")


def test_the_replays_script_gives_each_event_its_payload():
    sc = S.load(SMALL)
    script = Replay(sc, None, "test/script", log=lambda *a, **k: None)._prepare(sc.duration_s)
    assert isinstance(script, Script) and len(script) == len(sc.events)
    for ev, key, payload, src in script:
        assert M.decode(payload) == ev and key.startswith("test/script/") and src == "main"
    assert len(set(map(id, script.keys))) == len(set(script.keys)) < len(script) / 2   # positions repeat their keys
