"""UV messages: wire round trip and rejection of bad input, naming the field."""
import math

import msgpack
import pytest

from ea_agent.core.messages import VERSION, MessageError, decode, encode
from ea_agent.domains.uv.messages import UvAgent, UvSighting, UvState

GOOD = {
    UvState: {"t": 1.5, "robot": "UGV1", "lon": -117.1, "lat": 33.9, "speed_mps": 1.2, "heading_deg": 359.5,
              "sigma_m": 2.0, "mode": "moving"},
    UvSighting: {"t": 2.0, "robot": "UGV1", "target": "E1", "lon": -117.1, "lat": 33.9, "sigma_m": 3.0},
    UvAgent: {"t": 3.0, "sender": "UGV1", "to": "UGV2", "act": "delegate", "task": "P1", "target": "E1"},
}


def wire(cls, **change) -> bytes:
    d = dict(GOOD[cls], kind=cls.KIND, v=VERSION)
    for k, v in change.items():
        if v is ...:
            del d[k]
        else:
            d[k] = v
    return msgpack.packb(d, use_bin_type=True)


@pytest.mark.parametrize("cls", list(GOOD))
def test_round_trip(cls):
    msg = cls(**GOOD[cls])
    assert decode(encode(msg)) == msg
    assert decode(wire(cls)) == msg


def test_kinds_and_keys():
    assert (UvState.KIND, UvSighting.KIND, UvAgent.KIND) == ("uv-state", "uv-sighting", "uv-agent")
    assert UvState.KEY == "st/{place}/{robot}"
    assert UvSighting.KEY == "sgt/{place}/{robot}/{target}"
    assert UvAgent.KEY == "agm/{to}/{sender}"


def test_agent_target_optional_and_every_mode():
    assert decode(wire(UvAgent, target=...)).target is None
    for mode in ("moving", "paused", "waiting-gps"):
        assert decode(wire(UvState, mode=mode)).mode == mode


BAD = [
    (UvState, "speed_mps", 100.5), (UvState, "speed_mps", -1.0), (UvState, "speed_mps", math.nan),
    (UvState, "heading_deg", 360.0), (UvState, "heading_deg", -0.5), (UvState, "heading_deg", math.inf),
    (UvState, "lon", math.nan), (UvState, "lat", 91.0), (UvState, "t", -1.0), (UvState, "t", math.nan),
    (UvState, "mode", "flying"), (UvState, "robot", ""), (UvState, "robot", ...), (UvState, "sigma_m", -2.0),
    (UvState, "speed_mps", "fast"), (UvState, "heading_deg", True),
    (UvSighting, "target", ...), (UvSighting, "lon", 200.0), (UvSighting, "sigma_m", math.nan),
    (UvAgent, "act", "ping"), (UvAgent, "to", 7), (UvAgent, "task", ...), (UvAgent, "target", ""),
]


@pytest.mark.parametrize("cls,field,value", BAD)
def test_bad_input_rejected_naming_the_field(cls, field, value):
    with pytest.raises(MessageError) as e:
        decode(wire(cls, **{field: value}))
    assert e.value.field == field
    assert e.value.kind == cls.KIND
