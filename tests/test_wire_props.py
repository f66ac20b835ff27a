"""Property tests of the mesh's single entry point for network payloads.

`messages.decode`, `wire.decode_control` and `gate.Gate` must turn *any* input bytes
into either a message that satisfies the documented bounds or the project's own
rejection (`MessageError`, or None + a count from `Gate`) -- never any other exception.
"""
from __future__ import annotations

import math
import sys
from unittest import mock

import msgpack
import msgspec
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from saim_mesh.protocol import messages as M
from saim_mesh.protocol import gate as G
from saim_mesh.protocol import wire as W

SETTINGS = settings(max_examples=300, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

T_MAX = 3600.0          # a scenario end for the Gate tests
BIG = 2**30             # a size limit that never bites

# --------------------------------------------------------------------------- helpers


def packb(obj) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def raw_dict(payload: bytes) -> dict:
    """The msgpack map behind a valid encoded message (bytes stay bytes)."""
    return msgpack.unpackb(payload, raw=False, strict_map_key=False)


def decode_data_only_rejects(payload: bytes):
    """messages.decode: a message, or None when rejected with MessageError (anything else escapes)."""
    try:
        return M.decode(payload)
    except M.MessageError:
        return None


def decode_control_only_rejects(cls, payload: bytes, max_bytes: int = BIG):
    try:
        return W.decode_control(cls, payload, max_bytes)
    except M.MessageError:
        return None


def gate_all(payload: bytes, gate: G.Gate | None = None) -> None:
    """Feed one payload to every entry point; only the project's rejection may come out."""
    gate = gate or G.Gate(T_MAX)
    before = gate.rejects.total + gate.ok
    n = 1
    m = gate.data(payload, "fuzz/data")
    if m is not None:
        check_data(m, gate.t_max)
    for cls in W.CONTROL:
        n += 1
        c = gate.control(cls, payload, f"fuzz/{cls.__name__}")
        if c is not None:
            check_control(c, gate.t_max)
    assert gate.rejects.total + gate.ok == before + n, "every payload is either accepted or counted"
    assert sum(gate.rejects.by_kind.values()) == gate.rejects.total


def _nonempty_str(x) -> bool:
    return type(x) is str and len(x) > 0


def _finite_in(x, lo, hi) -> bool:
    return type(x) is float and math.isfinite(x) and lo <= x <= hi


def check_data(m, t_max: float = math.inf) -> None:
    """The documented bounds of a decoded data message."""
    assert type(m) in M.MESSAGE_TYPES.values()
    assert _finite_in(m.t, 0.0, t_max), m
    if hasattr(m, "lon"):
        assert _finite_in(m.lon, -180.0, 180.0), m
        assert _finite_in(m.lat, -90.0, 90.0), m
    if isinstance(m, M.LocationReport):
        assert _nonempty_str(m.entity)
    elif isinstance(m, M.SensorTrack):
        assert _nonempty_str(m.track) and _nonempty_str(m.source)
        assert type(m.strength) is int and m.strength >= 0
        assert m.heading is None or _finite_in(m.heading, 0.0, 360.0)
        assert m.speed is None or _finite_in(m.speed, 0.0, math.inf)
    elif isinstance(m, M.SensorHit):
        assert _nonempty_str(m.sensor)
    elif isinstance(m, M.MissionConfirm):
        assert _nonempty_str(m.mission) and _nonempty_str(m.unit)
        assert m.phase in ("start", "end") and m.source in ("message", "local")
    elif isinstance(m, M.Order):
        assert m.action in M.Order.ACTIONS
        assert _nonempty_str(m.plan) and _nonempty_str(m.issuer)
        assert m.mission is None or _nonempty_str(m.mission)
        assert m.mission is not None or not m.action.endswith("-mission")
    elif isinstance(m, M.CallForFire):   # and CallForFireConfirm
        assert _nonempty_str(m.cff) and _nonempty_str(m.requester)
        assert _finite_in(m.radius_m, 1.0, 100_000.0)
    elif isinstance(m, M.Reorganization):
        assert _nonempty_str(m.unit) and _nonempty_str(m.new_parent)
    elif isinstance(m, M.Alert):
        for name in ("owner", "type", "category", "message"):
            assert _nonempty_str(getattr(m, name))
        assert m.priority in M.PRIORITIES
        assert type(m.subjects) is tuple and all(type(s) is str for s in m.subjects)
        assert type(m.details) is dict


def _seq(x) -> bool:
    return type(x) is int and 0 <= x <= W.SEQ_LIMIT


def check_control(m, t_max: float = W.T_LIMIT) -> None:
    """The documented bounds of a decoded control struct."""
    assert type(m) in W.CONTROL
    assert type(m.v) is int and m.v == 1
    if hasattr(m, "t"):
        assert _finite_in(m.t, 0.0, min(t_max, W.T_LIMIT)), m
    if isinstance(m, W.Bye):
        assert type(m.unit) is str and 1 <= len(m.unit) <= 128


# --------------------------------------------------------------------------- strategies

text = st.text(alphabet=st.characters(codec="utf-8"), max_size=24)
name = st.text(alphabet=st.characters(codec="utf-8"), min_size=1, max_size=24)


def fl(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


EDGE_VALUES = [None, True, False, 0, 1, -1, 1.0, -0.0, 2, "1", "", b"", 2**53, 2**53 + 1, 2**63 - 1,
               2**64 - 1, -(2**63), math.nan, math.inf, -math.inf, 1e15, 1e300, -1e300, 5e-324,
               T_MAX + 1, W.T_LIMIT, W.T_LIMIT + 1, 181.0, -91.0, 360.0001, [], {}, "x" * 600]

ints_any = st.one_of(st.integers(-(2**63), 2**64 - 1),
                     st.sampled_from([2**64 - 1, -(2**63), 2**53, 2**53 + 1, 2**63, 2**32]))
floats_any = st.floats(allow_nan=True, allow_infinity=True)
leaf = st.one_of(st.none(), st.booleans(), ints_any, floats_any, text, st.binary(max_size=24),
                 st.sampled_from(EDGE_VALUES))
any_key = st.one_of(text, ints_any, st.binary(max_size=8), st.none(), st.booleans(), floats_any)
# arbitrary msgpack-able values: maps may have non-str keys (data decoding refuses them)
any_value = st.recursive(
    leaf,
    lambda ch: st.one_of(st.lists(ch, max_size=5), st.dictionaries(any_key, ch, max_size=5)),
    max_leaves=20,
)

# --- valid data messages, within bounds
t_data = fl(0.0, W.T_LIMIT)
lon, lat = fl(-180.0, 180.0), fl(-90.0, 90.0)
json_like = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-(2**63), 2**64 - 1), fl(-1e300, 1e300), text,
              st.binary(max_size=16)),
    lambda ch: st.one_of(st.lists(ch, max_size=4), st.dictionaries(text, ch, max_size=4)),
    max_leaves=12,
)
data_messages = st.one_of(
    st.builds(M.LocationReport, t_data, name, lon, lat),
    st.builds(M.SensorTrack, t_data, name, lon, lat, st.integers(0, 2**64 - 1),
              st.none() | fl(0.0, 360.0), st.none() | fl(0.0, 1e300), name),
    st.builds(M.SensorHit, t_data, name, lon, lat),
    st.builds(M.MissionConfirm, t_data, name, name, st.sampled_from(["start", "end"]),
              st.sampled_from(["message", "local"])),
    st.builds(M.Order, t_data, st.sampled_from(["execute-plan", "abort-plan"]), name, name),
    st.builds(M.Order, t_data, st.sampled_from(["start-mission", "end-mission"]), name, name, name),
    st.builds(M.CallForFire, t_data, name, name, lon, lat, fl(1.0, 100_000.0)),
    st.builds(M.CallForFireConfirm, t_data, name, name, lon, lat, fl(1.0, 100_000.0)),
    st.builds(M.Reorganization, t_data, name, name),
    st.builds(M.Alert, t_data, name, name, name, st.sampled_from(M.PRIORITIES),
              st.lists(text, max_size=5).map(tuple), name, st.dictionaries(text, json_like, max_size=4)),
)

# --- valid control messages, within bounds
t_ctl = fl(0.0, W.T_LIMIT)
seq = st.integers(0, W.SEQ_LIMIT)
control_messages = st.one_of(
    st.builds(W.Ack, t=t_ctl),
    st.builds(W.Bye, unit=st.text(alphabet=st.characters(codec="utf-8"), min_size=1, max_size=128)),
)

# fixed, valid samples of every kind for the mutation tests
DATA_SAMPLES = [
    M.LocationReport(1.0, "A1S1E01", -116.5, 35.3),
    M.SensorTrack(2.0, "H1", -116.5, 35.3, 4, 180.0, 3.0, "fusion"),
    M.SensorHit(2.5, "S1", -116.5, 35.3),
    M.MissionConfirm(3.0, "A1-move", "A1", "start", "local"),
    M.Order(4.0, "execute-plan", "withdrawal", "BN"),
    M.Order(4.5, "start-mission", "main", "BN", "M-march"),
    M.CallForFire(5.0, "CFF-1", "A2", -116.5, 35.3, 600.0),
    M.CallForFireConfirm(6.0, "CFF-1", "A2", -116.5, 35.3, 600.0),
    M.Reorganization(7.0, "R", "BN"),
    M.Alert(8.0, "BN", "contact", "adversarial-activity", "flash", ("A1", "H4"), "Contact", {"x": 1}),
    M.UvState(9.0, "UGV1", -116.5, 35.3, 1.5, 270.0, 2.0, "moving"),
    M.UvSighting(9.5, "UAV1", "EV1", -116.5, 35.3, 3.0),
    M.UvAgent(10.0, "UGV1", "UGV2", "delegate", "pursue", "EV1"),
]
CONTROL_SAMPLES = [
    W.make(W.Ack, t=10.0),
    W.make(W.Bye, unit="A1"),
    *([W.make(W.AckCmd, req="r1", alert="A2/3", by="cdr"),
       W.make(W.SilenceCmd, req="r2", id="s1", types=["contact"], subjects=["A2"], areas=[], until_t=600.0,
              comment="known"),
       W.make(W.UnsilenceCmd, req="r3", id="s1"),
       W.make(W.SetCmd, req="r4", key="voi.out_of_position_m", value=500.0),
       W.make(W.ConfirmCmd, req="r5", mission="m1", phase="start"),
       W.make(W.CffCmd, req="r6", cff="cff1", action="confirm"),
       W.make(W.DecideCmd, req="r7", alert="BN/27", option="execute:BN-branch-ABF"),
       W.make(W.InhibitCmd, req="r8", id="contact-mutes-distance", source=W.MatcherSpec(types=["contact"]),
              target=W.MatcherSpec(types=["distance", "strength"], priorities=["immediate"]), equal=["subjects"],
              for_s=600.0, comment="known contact"),
       W.make(W.UninhibitCmd, req="r9", id="contact-mutes-distance"),
       W.make(W.Notice, kind="escalate", t=1242.0, owner="A2", alert="A2/1", story="A2/1", type="out-of-position",
              priority="immediate", subjects=["A2"], message="off route", count=1, to="A", due_t=942.0),
       W.make(W.CmdResult, req="r1", kind="ack", ok=True, error="", t=12.0)] if hasattr(W, "CmdResult") else []),
]


def test_samples_cover_every_kind():
    """The samples used below must cover every data kind and every control struct."""
    assert {m.KIND for m in DATA_SAMPLES} == set(M.MESSAGE_TYPES)
    assert {type(m) for m in CONTROL_SAMPLES} == set(W.CONTROL)


@st.composite
def mutated(draw, samples, enc):
    """A valid message's map with one field replaced, dropped or added (or a few of those)."""
    m = draw(st.sampled_from(samples))
    d = raw_dict(enc(m))
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["set", "set", "drop", "add"]))
        keys = sorted(d, key=repr)
        if op == "set" and keys:
            d[draw(st.sampled_from(keys))] = draw(any_value)
        elif op == "drop" and keys:
            del d[draw(st.sampled_from(keys))]
        else:
            d[draw(any_key)] = draw(any_value)
    return type(m), d


def pack_or_none(obj):
    try:
        return packb(obj)
    except (TypeError, ValueError, OverflowError):   # e.g. unhashable/unsupported: not a wire payload
        return None


# --------------------------------------------------------------------------- 1. arbitrary bytes


@SETTINGS
@given(st.binary(max_size=512))
@example(b"")
@example(b"\xc1")
@example(b"\x80")
@example(b"\xdd\xff\xff\xff\xff")          # array32 claiming 4G items
@example(b"\xdf\xff\xff\xff\xff")          # map32 claiming 4G entries
@example(b"\x81\xa1v\xc3")                 # {"v": True}
def test_arbitrary_bytes_only_message_error(payload):
    m = decode_data_only_rejects(payload)
    if m is not None:
        check_data(m)
    for cls in W.CONTROL:
        c = decode_control_only_rejects(cls, payload)
        if c is not None:
            check_control(c)
    gate_all(payload)


# --------------------------------------------------------------------------- 2. structure-aware


@SETTINGS
@given(any_value)
def test_arbitrary_msgpack_values_only_message_error(value):
    payload = pack_or_none(value)
    if payload is None:
        return
    m = decode_data_only_rejects(payload)
    if m is not None:
        check_data(m)
    for cls in W.CONTROL:
        c = decode_control_only_rejects(cls, payload)
        if c is not None:
            check_control(c)
    gate_all(payload)


@SETTINGS
@given(mutated(DATA_SAMPLES, M.encode))
def test_mutated_data_messages(case):
    _, d = case
    payload = pack_or_none(d)
    if payload is None:
        return
    m = decode_data_only_rejects(payload)
    if m is not None:
        check_data(m)
        assert type(d.get("v")) is int and d["v"] == 1, "only an exact integer 1 is version 1"
        assert type(m) is M.MESSAGE_TYPES[d["kind"]]
    gate = G.Gate(T_MAX)
    g = gate.data(payload, "fuzz/data")
    if g is not None:
        check_data(g, T_MAX)
        assert M.encode(g) == M.encode(m)      # (not `==`: a NaN inside Alert.details is != itself)
    else:
        assert gate.rejects.total == 1
    gate_all(payload)


@SETTINGS
@given(mutated(CONTROL_SAMPLES, W.encode))
def test_mutated_control_messages(case):
    cls, d = case
    payload = pack_or_none(d)
    if payload is None:
        return
    c = decode_control_only_rejects(cls, payload)
    if c is not None:
        check_control(c)
        # (a *missing* `v` is covered by test_version_control_rejected)
        assert "v" not in d or (type(d["v"]) is int and d["v"] == 1), "only an exact integer 1 is version 1"
    gate = G.Gate(T_MAX)
    g = gate.control(cls, payload, "fuzz/ctl")
    if g is not None:
        check_control(g, T_MAX)
        assert g == c
    else:
        assert gate.rejects.total == 1
    gate_all(payload)


def _deep(depth: int, container: str) -> bytes:
    """A msgpack value nested `depth` levels deep (raw bytes: the packer refuses > 511)."""
    return (b"\x91" if container == "list" else b"\x81\xa1a") * depth + b"\xc0"


def _map_with_raw(fields: dict, raw_name: str, raw_value: bytes) -> bytes:
    items = [packb(k) + packb(v) for k, v in fields.items() if k != raw_name]
    items.append(packb(raw_name) + raw_value)
    assert len(items) < 16
    return bytes([0x80 | len(items)]) + b"".join(items)


@SETTINGS
@given(depth=st.integers(1, 1024), container=st.sampled_from(["list", "map"]),
       sample=st.sampled_from(DATA_SAMPLES + CONTROL_SAMPLES),
       where=st.sampled_from(["kind", "v", "t", "details", "extra"]), good_v=st.booleans())
@example(depth=1000, container="list", sample=DATA_SAMPLES[0], where="kind", good_v=False)
@example(depth=1000, container="list", sample=DATA_SAMPLES[0], where="kind", good_v=True)
@example(depth=1000, container="map", sample=DATA_SAMPLES[0], where="v", good_v=True)
def test_deeply_nested_values_only_message_error(depth, container, sample, where, good_v):
    """msgpack itself accepts nesting up to 1024 levels; nothing downstream may choke on it."""
    enc = W.encode if isinstance(sample, msgspec.Struct) else M.encode
    d = raw_dict(enc(sample))
    if not good_v:
        d["v"] = 2
    payload = _map_with_raw(d, where, _deep(depth, container))
    decode_data_only_rejects(payload)
    for cls in W.CONTROL:
        decode_control_only_rejects(cls, payload)
    gate_all(payload)


@pytest.mark.parametrize("depth", [990, 1000, 1024])
@pytest.mark.parametrize("container", ["list", "map"])
@pytest.mark.parametrize("where, good_v", [("kind", False), ("kind", True), ("v", True), ("entity", True),
                                           ("extra", True)])
def test_deeply_nested_values_at_default_recursion_limit(depth, container, where, good_v):
    """The same as above outside Hypothesis, which raises the recursion limit while a test runs
    and so hides failures that a peer (at Python's default limit) would hit."""
    assert sys.getrecursionlimit() <= 1000 + 100, "run at (about) Python's default recursion limit"
    d = raw_dict(M.encode(DATA_SAMPLES[0]))
    if not good_v:
        d["v"] = 2
    payload = _map_with_raw(d, where, _deep(depth, container))
    decode_data_only_rejects(payload)
    for cls in W.CONTROL:
        decode_control_only_rejects(cls, payload)
    gate_all(payload)


# --------------------------------------------------------------------------- 3. round trip


@SETTINGS
@given(data_messages)
def test_data_round_trip(m):
    payload = M.encode(m)
    assert M.decode(payload) == m
    gate = G.Gate(W.T_LIMIT, max_bytes=BIG)
    assert gate.data(payload, "rt") == m
    assert gate.ok == 1 and gate.rejects.total == 0


@SETTINGS
@given(control_messages)
def test_control_round_trip(m):
    payload = W.encode(m)
    assert W.decode_control(type(m), payload, BIG) == m
    gate = G.Gate(W.T_LIMIT, max_bytes=BIG)
    assert gate.control(type(m), payload, "rt") == m
    assert gate.ok == 1 and gate.rejects.total == 0


# --------------------------------------------------------------------------- 4. size bound


def _padded_location(size: int) -> bytes:
    for n in range(1, 4 * size):
        p = M.encode(M.LocationReport(1.0, "E" * n, 1.0, 2.0))
        if len(p) == size:
            return p
    raise AssertionError(f"no location message of {size} bytes")


def _padded_control(cls, size: int) -> bytes:
    for n in range(1, 4 * size):
        m = W.make(W.Bye, unit="U" * n) if cls is W.Bye else W.make(W.AckCmd, req="r1", alert="U" * n)
        p = W.encode(m)
        if len(p) == size:
            return p
    raise AssertionError(f"no {cls.__name__} of {size} bytes")


class _Spy:
    """Stands in for a msgspec decoder and records whether it was asked to decode."""

    def __init__(self, real):
        self.real, self.calls = real, 0

    def decode(self, data):
        self.calls += 1
        return self.real.decode(data)


def test_size_bound_data_rejected_before_decoding():
    gate = G.Gate(T_MAX, max_bytes=100)
    over, at = _padded_location(101), _padded_location(100)
    assert M.decode(over).KIND == "location"            # valid, only too big
    with mock.patch.object(M, "decode", wraps=M.decode) as spy:
        assert gate.data(over, "k") is None
        assert spy.call_count == 0, "an oversized payload must not be decoded"
        assert gate.data(at, "k") is not None            # exactly the limit is fine
        assert spy.call_count == 1
    assert gate.rejects.total == 1 and sum(gate.rejects.by_kind.values()) == 1
    assert len(gate.rejects.by_kind) == 1


@pytest.mark.parametrize("cls", [W.Bye, W.AckCmd])
def test_size_bound_control_rejected_before_decoding(cls):
    limit = 100
    gate = G.Gate(T_MAX, max_bytes=limit)
    over, at = _padded_control(cls, limit + 1), _padded_control(cls, limit)
    spy = _Spy(W._DECODERS[cls])
    with mock.patch.dict(W._DECODERS, {cls: spy}):
        assert gate.control(cls, over, "k") is None
        assert spy.calls == 0, "an oversized payload must not be decoded"
        assert gate.control(cls, at, "k") is not None
        assert spy.calls == 1
        with pytest.raises(M.MessageError):
            W.decode_control(cls, over, limit)
        assert spy.calls == 1
    assert gate.rejects.total == 1 and gate.rejects.by_kind == {cls.__name__.lower(): 1}


@SETTINGS
@given(m=st.one_of(data_messages, control_messages), slack=st.integers(-64, 64))
def test_size_bound_property(m, slack):
    """Any valid payload: rejected uncounted-as-ok and undecoded iff it exceeds the limit."""
    is_ctl = isinstance(m, msgspec.Struct)
    payload = W.encode(m) if is_ctl else M.encode(m)
    limit = max(0, len(payload) + slack)
    gate = G.Gate(W.T_LIMIT, max_bytes=limit)
    if is_ctl:
        spy = _Spy(W._DECODERS[type(m)])
        with mock.patch.dict(W._DECODERS, {type(m): spy}):
            got = gate.control(type(m), payload, "k")
        calls = spy.calls
    else:
        with mock.patch.object(M, "decode", wraps=M.decode) as dspy:
            got = gate.data(payload, "k")
        calls = dspy.call_count
    if len(payload) > limit:
        assert got is None and calls == 0
        assert gate.rejects.total == 1 and sum(gate.rejects.by_kind.values()) == 1
    else:
        assert got == m and calls == 1


# --------------------------------------------------------------------------- 5. version

MISSING = object()
BAD_VERSIONS = [True, 1.0, 2, "1", MISSING, False, 0, -1, None, b"\x01", [1], 2**64 - 1]


def _vid(v):
    return "missing" if v is MISSING else repr(v)


def _with_version(d: dict, v) -> bytes:
    d = dict(d)
    if v is MISSING:
        d.pop("v", None)
    else:
        d["v"] = v
    return packb(d)


@pytest.mark.parametrize("v", BAD_VERSIONS, ids=_vid)
@pytest.mark.parametrize("sample", DATA_SAMPLES, ids=lambda m: m.KIND)
def test_version_data_rejected(sample, v):
    payload = _with_version(raw_dict(M.encode(sample)), v)
    with pytest.raises(M.MessageError) as ei:
        M.decode(payload)
    assert ei.value.field == "v"
    gate = G.Gate(T_MAX)
    assert gate.data(payload) is None and gate.rejects.total == 1
    assert M.decode(_with_version(raw_dict(M.encode(sample)), 1)) == sample   # the control case


@pytest.mark.parametrize("v", BAD_VERSIONS, ids=_vid)
@pytest.mark.parametrize("sample", CONTROL_SAMPLES, ids=lambda m: type(m).__name__)
def test_version_control_rejected(sample, v):
    cls = type(sample)
    payload = _with_version(raw_dict(W.encode(sample)), v)
    with pytest.raises(M.MessageError):
        W.decode_control(cls, payload, BIG)
    gate = G.Gate(T_MAX)
    assert gate.control(cls, payload) is None and gate.rejects.total == 1
    assert W.decode_control(cls, _with_version(raw_dict(W.encode(sample)), 1), BIG) == sample


# --------------------------------------------------------------------------- 6. time bound

BAD_TIMES = [T_MAX + 1, 1e15, math.nan, math.inf, -math.inf, -1.0, -1, 2**64 - 1]
TIMED_CONTROL = [s for s in CONTROL_SAMPLES if hasattr(s, "t")]


@pytest.mark.parametrize("t", BAD_TIMES, ids=repr)
@pytest.mark.parametrize("sample", DATA_SAMPLES, ids=lambda m: m.KIND)
def test_time_bound_data(sample, t):
    d = raw_dict(M.encode(sample))
    d["t"] = t
    gate = G.Gate(T_MAX)
    assert gate.data(packb(d), "k") is None
    assert gate.rejects.total == 1 and gate.ok == 0
    d["t"] = T_MAX                                      # the end itself is inside the clock
    assert gate.data(packb(d), "k") is not None


@pytest.mark.parametrize("t", BAD_TIMES, ids=repr)
@pytest.mark.parametrize("sample", TIMED_CONTROL, ids=lambda m: type(m).__name__)
def test_time_bound_control(sample, t):
    cls = type(sample)
    d = raw_dict(W.encode(sample))
    d["t"] = t
    gate = G.Gate(T_MAX)
    assert gate.control(cls, packb(d), "k") is None
    assert gate.rejects.total == 1 and gate.ok == 0
    d["t"] = T_MAX
    assert gate.control(cls, packb(d), "k") is not None


@SETTINGS
@given(t_max=fl(0.0, W.T_LIMIT), t=st.one_of(floats_any, ints_any),
       sample=st.sampled_from(DATA_SAMPLES + TIMED_CONTROL))
def test_time_bound_property(t_max, t, sample):
    is_ctl = isinstance(sample, msgspec.Struct)
    d = raw_dict(W.encode(sample) if is_ctl else M.encode(sample))
    d["t"] = t
    gate = G.Gate(t_max)
    got = gate.control(type(sample), packb(d)) if is_ctl else gate.data(packb(d))
    ok = isinstance(t, (int, float)) and not isinstance(t, bool) and 0 <= t <= t_max
    if got is None:
        assert not ok, f"t={t!r} inside [0, {t_max}] was rejected"
    else:
        assert ok, f"t={t!r} outside [0, {t_max}] was accepted"
        assert got.t == float(t) and math.isfinite(got.t)


# --------------------------------------------------------------------------- 7. bounded logging


def _bad_payloads(n: int):
    """A varied flood of bad payloads from a fixed set of shapes (the kinds stay few)."""
    loc = raw_dict(M.encode(DATA_SAMPLES[0]))
    shapes = [
        b"\xc1garbage",
        b"",
        packb([1, 2, 3]),
        packb({**loc, "v": True}),
        packb({**loc, "lat": math.nan}),
        packb({**loc, "t": T_MAX + 1}),
        packb({**raw_dict(M.encode(DATA_SAMPLES[1])), "strength": -1}),
        b"x" * 70_000,                                  # over the default size bound
    ]
    for i in range(n):
        yield shapes[i % len(shapes)]


def test_rejects_log_bounded_fixed_kinds():
    calls = []
    gate = G.Gate(T_MAX, log=lambda *a, **k: calls.append(a))
    for i, p in enumerate(_bad_payloads(10_000)):
        assert gate.data(p, f"saim/x/{i}") is None
    r = gate.rejects
    assert r.total == 10_000 and gate.ok == 0
    assert sum(r.by_kind.values()) == 10_000
    assert len(r.recent) <= 20
    # the first of each kind, plus at most a few rate-limited summaries (every 10 s of wall time)
    assert len(calls) <= len(r.by_kind) + 3, calls[:10]
    assert len(calls) <= 15


def test_rejects_log_bounded_attacker_chosen_kinds():
    """The kind a reject is counted under must not be chosen freely by the sender: a flood of
    payloads each with a fresh `kind` string must still cost counters, not log lines or memory."""
    calls = []
    gate = G.Gate(T_MAX, log=lambda *a, **k: calls.append(a))
    for i in range(10_000):
        if i % 2:
            p = packb({"v": 1, "kind": f"kind-{i}", "t": 1.0})          # unknown kind
        else:
            p = packb({"v": 2, "kind": f"kind-{i}", "t": 1.0})          # bad version
        assert gate.data(p, "saim/x") is None
    r = gate.rejects
    assert r.total == 10_000
    assert len(calls) <= 15, f"{len(calls)} log calls, e.g. {calls[:3]}"
    assert len(r.by_kind) <= 50, f"by_kind grew to {len(r.by_kind)} keys"


def test_rejects_log_bounded_control():
    calls = []
    gate = G.Gate(T_MAX, log=lambda *a, **k: calls.append(a))
    for i in range(10_000):
        cls = W.CONTROL[i % len(W.CONTROL)]
        assert gate.control(cls, b"\xc1" if i % 3 else None, f"k{i}") is None
    r = gate.rejects
    assert r.total == 10_000
    assert len(calls) <= len(W.CONTROL) + 3
