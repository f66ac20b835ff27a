"""The fixed-prefix fast path of `messages.decode` (kind and version first on the wire):
never more lenient than the validating path, and used for what `encode` writes."""
from __future__ import annotations

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ea_agent.core.messages as CM
from saim_mesh.protocol import messages as M


def slow(data: bytes, monkeypatch):
    """The same bytes through the paths before the prefix: its verdict, or the error's field."""
    with monkeypatch.context() as mp:
        mp.setattr(CM, "_PREFIXED", {})
        try:
            return CM.decode(data)
        except M.MessageError as e:
            return ("refused", e.kind, e.field)


def fast(data: bytes):
    try:
        return CM.decode(data)
    except M.MessageError as e:
        return ("refused", e.kind, e.field)


def test_encode_writes_kind_and_version_first_and_decode_takes_the_prefix(monkeypatch):
    m = M.LocationReport(t=12.5, entity="A1S1", lon=-116.5, lat=35.25)
    b = M.encode(m)
    assert b.startswith(b"\x86\xa4kind\xa8location\xa1v\x01")
    calls = []

    class Spy:
        def __init__(self, d):
            self.d = d

        def decode(self, data):
            calls.append(data)
            return self.d.decode(data)
    monkeypatch.setattr(CM, "_PREFIXED", {k: Spy(d) for k, d in CM._PREFIXED.items()})
    assert CM.decode(b) == m
    assert calls == [b]


def test_a_kind_with_optional_fields_has_no_prefix():
    """A map that leaves an optional field out could carry a second `kind` in its place."""
    assert CM._prefix(M.SensorTrack) is None
    assert CM._prefix(M.LocationReport) is not None


KEYS = st.sampled_from(["kind", "v", "t", "entity", "lon", "lat", "x"])
VALUES = st.one_of(st.sampled_from(["location", "track", "A1", "", "order"]), st.integers(-2, 3),
                   st.floats(allow_nan=True, allow_infinity=True), st.none(),
                   st.dictionaries(st.sampled_from(["kind", "v"]), st.sampled_from(["location", 1]), max_size=2))


@settings(max_examples=400, deadline=None)
@given(st.lists(st.tuples(KEYS, VALUES), max_size=8), st.booleans())
def test_a_map_behind_the_location_prefix_decodes_as_the_validating_path_says(pairs, dup_header):
    """Whatever follows `kind: location, v: 1` (a second kind, a field twice, a field
    missing, an unknown key, a nested map spelling the kind), the verdict is the one the
    paths without the prefix give."""
    body = b"".join(msgpack.packb(k) + msgpack.packb(v) for k, v in pairs)
    n = len(pairs) + 2 if not dup_header else 6   # a header that lies about the count too
    data = bytes([0x80 + min(n, 15)]) + b"\xa4kind\xa8location\xa1v\x01" + body
    with pytest.MonkeyPatch.context() as mp:
        want = slow(data, mp)
    assert fast(data) == want
