import math

import msgpack
import pytest

from saim_mesh.protocol import messages as M

SAMPLES = [
    M.LocationReport(1.0, "A1S1E01", -116.5, 35.3),
    M.SensorTrack(2.0, "H1", -116.5, 35.3, 4, 180.0, 3.0, "fusion"),
    M.MissionConfirm(3.0, "A1-move", "A1", "start", "local"),
    M.Order(4.0, "execute-plan", "withdrawal", "BN"),
    M.CallForFire(5.0, "CFF-1", "A2", -116.5, 35.3, 600.0),
    M.CallForFireConfirm(6.0, "CFF-1", "A2", -116.5, 35.3, 600.0),
    M.Reorganization(7.0, "R", "BN"),
    M.Alert(8.0, "BN", "contact", "adversarial-activity", "flash", ("A1", "H4"), "Contact", {"x": 1}),
]


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: m.KIND)
def test_roundtrip(msg):
    assert M.decode(M.encode(msg)) == msg


def _wire(**d):
    d.setdefault("v", M.VERSION)
    return msgpack.packb(d)


@pytest.mark.parametrize("payload, field", [
    (_wire(kind="location", t=1.0, entity="E", lon=1.0), "lat"),
    (_wire(kind="location", t=1.0, entity="E", lon=1.0, lat=math.nan), "lat"),
    (_wire(kind="location", t=1.0, entity="E", lon=181.0, lat=1.0), "lon"),
    (_wire(kind="location", t=-1.0, entity="E", lon=1.0, lat=1.0), "t"),
    (_wire(kind="location", t=1.0, entity="", lon=1.0, lat=1.0), "entity"),
    (_wire(kind="track", t=1.0, track="H", lon=1.0, lat=1.0, strength=-2), "strength"),
    (_wire(kind="mission", t=1.0, mission="m", unit="u", phase="middle"), "phase"),
    (_wire(kind="teleport", t=1.0), "kind"),
    (_wire(kind="location", t=1.0, entity="E", lon=1.0, lat=1.0, v=99), "v"),
    (b"\xc1\xc1garbage", "(bytes)"),
    (msgpack.packb([1, 2, 3]), "(message)"),
])
def test_bad_messages_name_the_field(payload, field):
    with pytest.raises(M.MessageError) as e:
        M.decode(payload)
    assert e.value.field == field
    assert field in str(e.value)


def test_decoder_counts_and_survives_bad_input():
    dec = M.Decoder()
    good = M.encode(SAMPLES[0])
    out = [dec(x) for x in (good, b"\x00junk", _wire(kind="location", t=1.0, entity="E", lon=1.0, lat=1e9), good)]
    assert out[0] == SAMPLES[0] and out[3] == SAMPLES[0]
    assert out[1] is None and out[2] is None
    assert (dec.ok, dec.errors) == (2, 2)
    assert "lat" in dec.recent[-1]


# -- typed decoding (msgspec structs) agrees with the validating dict path --------------------
UV_SAMPLES = [M.UvState(1.0, "R1", -116.5, 35.3, 2.0, 359.5, 3.0, "moving"),
              M.UvSighting(2.0, "R1", "T1", -116.5, 35.3, 5.0),
              M.UvAgent(3.0, "R1", "R2", "delegate", "pursue", "T1")]
BAD_VALUES = [math.nan, math.inf, -math.inf, True, "x", "", None, -1.0, 1e9, 360.0, [1.0], {"a": 1}, 2**63 - 1, -(2**63)]


def _outcome(payload):
    try:
        return M.decode(payload)
    except M.MessageError as e:
        return ("error", e.field)


def _dict_outcome(d):
    try:
        return M.from_dict(d)
    except M.MessageError as e:
        return ("error", e.field)


@pytest.mark.parametrize("msg", [m for m in SAMPLES + UV_SAMPLES if getattr(type(m), "TYPED", False)],
                         ids=lambda m: m.KIND)
def test_typed_decoding_is_never_more_lenient_than_the_field_checks(msg):
    """Every field set to every odd value, or left out: the typed decoder gives the same
    message, or the same error naming the same field, as the dict-then-fields path."""
    base = M.to_dict(msg)
    base["v"] = M.VERSION
    cases = [dict(base, **{f: bad}) for f in base if f not in ("kind", "v") for bad in BAD_VALUES]
    cases += [{k: v for k, v in base.items() if k != f} for f in base if f not in ("kind", "v")]
    cases += [dict(base, extra=1), dict(base, at=base.get("t", 0) + 5.0), dict(base, action="start-mission")]
    for d in cases:
        got, want = _outcome(msgpack.packb(d, use_bin_type=True)), _dict_outcome(d)
        assert got == want, d
        if not isinstance(got, tuple):   # the same values of the same types
            assert [type(getattr(got, f)) for f in got.__dataclass_fields__] == \
                [type(getattr(want, f)) for f in want.__dataclass_fields__], d


def test_typed_decoding_keeps_numbers_as_floats():
    d = {"v": M.VERSION, "kind": "location", "t": 3, "entity": "E", "lon": 1, "lat": 2}
    m = M.decode(msgpack.packb(d))
    assert m == M.LocationReport(3.0, "E", 1.0, 2.0) and all(type(x) is float for x in (m.t, m.lon, m.lat))


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: m.KIND)
def test_any_bytes_like_payload_decodes(msg):
    """A payload handed over as a bytearray or memoryview (a socket's buffer) decodes like
    bytes: an unhashable slice used to raise TypeError out of the fast path."""
    b = M.encode(msg)
    assert M.decode(bytearray(b)) == msg
    assert M.decode(memoryview(b)) == msg


def test_a_bytes_like_bad_payload_is_refused_by_name():
    with pytest.raises(M.MessageError):
        M.decode(bytearray(b"\xc1\xc1garbage"))
