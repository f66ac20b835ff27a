import math

import msgpack
import pytest

from saim_mesh import messages as M

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
