"""A peer's per-key facts: learned once, `wanted` asked again after a re-registration,
keys not heard between two sweeps forgotten, the cache bounded."""
from __future__ import annotations

from dissemination.keyspace import KeySpace
from saim_mesh import batch as B
from saim_mesh import messages as M
from saim_mesh.keyfacts import KeyFacts

ROOT = "saim/kf"


def _facts(want, max_keys: int = 8192) -> tuple[KeyFacts, list]:
    asked: list[str] = []

    def test(key: str) -> bool:
        asked.append(key)
        return want(key)
    return KeyFacts(KeySpace(ROOT), B.groups_of(ROOT), test, max_keys), asked


def test_a_key_is_learned_once_per_interest_and_wanted_is_asked_again_after_a_new_one():
    kf, asked = _facts(lambda k: "/A1/" in k)
    k = f"{ROOT}/pos/X1Y1/x1y1/BN/A/A1/A1S1/A1S1E01"
    f = kf.learn(k)
    assert f.wanted and f.group == f"{ROOT}/pos/X1Y1/_b/BN/A" and asked == [k]
    assert kf.get(k) is f and f.gen == kf.gen
    kf.reset(lambda key: False)
    assert kf.get(k).gen != kf.gen            # stale: the hot path learns it again
    g = kf.of(k)
    assert g is f and not g.wanted and kf.of(k).gen == kf.gen and g.group == f"{ROOT}/pos/X1Y1/_b/BN/A"


def test_a_sweep_forgets_the_keys_not_heard_since_the_sweep_before():
    kf, _ = _facts(lambda k: True)
    old, live = f"{ROOT}/pos/X1Y1/x1y1/BN/A/A1/A1S1/A1S1E01", f"{ROOT}/pos/X1Y1/x1y2/BN/A/A1/A1S1/A1S1E02"
    kf.learn(old)
    kf.learn(live)
    assert kf.sweep() == 0                # both heard since the start
    kf.of(live)                           # heard again (the hot path's `of`)
    assert kf.sweep() == 1 and live in kf and old not in kf
    kf.reset(lambda k: True)              # a new interest: `live` is learned again, and so heard
    kf.of(live)
    assert kf.sweep() == 0 and live in kf
    assert kf.sweep() == 1 and not kf     # heard by nobody since


def test_an_interest_forgets_no_key():
    kf, _ = _facts(lambda k: True, max_keys=64)
    old = f"{ROOT}/pos/X1Y1/x1y1/BN/A/A1/A1S1/A1S1E01"
    kf.learn(old)
    for _ in range(3):
        kf.reset(lambda k: True)
    assert old in kf


def test_the_cache_is_bounded():
    kf, _ = _facts(lambda k: True, max_keys=64)
    for i in range(500):
        kf.learn(f"{ROOT}/pos/X1Y1/x1y1/BN/A/A1/A1S1/A1S1E{i:03d}")
    assert len(kf) <= 64


def test_checks_say_which_fields_a_key_names_and_why_a_message_does_not_belong():
    kf, _ = _facts(lambda k: True)
    k = f"{ROOT}/pos/X1Y1/x1y1/BN/A/A1/A1S1/A1S1E01"
    f = kf.learn(k)
    attrs, values = kf.checks(f, k, M.LocationReport)
    assert attrs is not None and "A1S1E01" in values and len(attrs) == len(values)
    assert f.cls is M.LocationReport and (f.attrs, f.values) == (attrs, values)
    attrs2, why = kf.checks(f, k, M.Alert)             # another class on the same key: not kept
    assert attrs2 is None and "pos/ keys" in why and f.cls is M.LocationReport


def test_an_entitys_keys_in_different_cells_share_one_copy_of_what_they_check():
    kf, _ = _facts(lambda k: True)
    a, b = f"{ROOT}/pos/X1Y1/x1y1/BN/A/A1/A1S1/A1S1E01", f"{ROOT}/pos/X1Y1/x1y2/BN/A/A1/A1S1/A1S1E01"
    _, va = kf.checks(kf.learn(a), a, M.LocationReport)
    _, vb = kf.checks(kf.learn(b), b, M.LocationReport)
    assert va == vb and va is vb
    c = f"{ROOT}/pos/X1Y1/x1y2/BN/A/A1/A1S1/A1S1E02"
    _, vc = kf.checks(kf.learn(c), c, M.LocationReport)
    assert "A1S1E02" in vc and vc != va
    kf.of(c)
    kf.sweep()
    kf.sweep()   # every key gone: so is every shared copy
    assert not kf and not kf._values
