"""VOA: suppression by time, repeat ratios, expiry, also-records, merging, off switch."""
from ea_agent.core.alert import Candidate
from ea_agent.core.config import load_config
from ea_agent.core.voa import Voa


def cand(t, measure=None, typ="out-of-position", key=("oop", "A1"), friendly=True, group=None, prio="immediate",
         news=False):
    return Candidate(t, typ, prio, ("A1",), "m", key=key, measure=measure, friendly=friendly, merge_group=group,
                     news=news)


def voa(**kw):
    return Voa(load_config(overrides={"voa": kw} if kw else None),
               merge_fn=lambda k, cs: Candidate(cs[0].t, "proximity", "flash", ("X",), "merged", key=k))


def test_suppression_by_time_friendly_and_hostile():
    v = voa()
    assert len(v.judge([cand(0, 200)])) == 1
    assert v.judge([cand(119, 1000)]) == []                      # friendly: 120 s
    h = voa()
    h.judge([cand(0, 2, typ="distance", key=("t",), friendly=False)])
    assert h.judge([cand(89, 9, typ="distance", key=("t",), friendly=False)]) == []   # hostile: 90 s
    assert len(h.judge([cand(91, 9, typ="distance", key=("t",), friendly=False)])) == 1
    assert h.stats["suppressed-time"] == 1


def test_repeat_needs_ratio_and_is_lower_priority():
    v = voa()
    v.judge([cand(0, 200)])
    assert v.judge([cand(200, 390)]) == []                        # not 2x worse
    out = v.judge([cand(300, 400)])
    assert len(out) == 1 and out[0].repeat and out[0].priority == "priority"
    assert v.stats["suppressed-not-worse"] == 1


def test_once_types_never_repeat_until_expiry():
    v = voa()
    c = lambda t: cand(t, None, typ="contingency", key=("c", 1))
    assert len(v.judge([c(0)])) == 1
    assert len(v.judge([c(720)])) == 1                            # quiet for 12 min: expired, told again
    assert v.judge([c(1000)]) == []


def test_a_story_that_goes_on_does_not_expire():
    """A candidate on the key, suppressed or not, or a touch, says the story is still
    going on: it is not told again as if the user had forgotten it."""
    v = voa()
    c = lambda t: cand(t, None, typ="contingency", key=("c", 1))
    assert len(v.judge([c(0)])) == 1
    assert v.judge([c(500)]) == []                                # suppressed, but the story is active at 500
    assert v.judge([c(1000)]) == []                               # 1000 s after the alert, 500 after the story
    v.touch(("c", 1), 1600)
    assert v.judge([c(2000)]) == []
    assert len(v.judge([c(2800)])) == 1                           # 800 s with nothing: forgotten
    assert v.last(("c", 1), 2800).t == 2800


def test_news_is_given_whatever_the_history():
    v = voa()
    c = lambda t, news: cand(t, 5.0, typ="monitored", key=("m", "NAI-1"), news=news)
    assert len(v.judge([c(0, False)])) == 1
    assert v.judge([c(10, False)]) == []                          # same group, inside the suppression interval
    assert len(v.judge([c(20, True)])) == 1                       # a new group in the area


def test_expiry_is_configurable():
    v = voa(expiry_s=100.0, suppress_friendly_s=10.0)
    v.judge([cand(0, 200)])
    assert v.judge([cand(50, 210)]) == []
    assert v.judge([cand(149, 210)]) == []                        # the story was active at 50
    out = v.judge([cand(250, 210)])
    assert len(out) == 1 and not out[0].repeat


def test_also_records_set_baselines():
    v = voa()
    c = cand(0, None, typ="contact", key=("threat", "A1", "contact"), friendly=False)
    c.also = ((("threat", "A1", "distance"), 1.0),)
    v.judge([c])
    d = lambda t, m: cand(t, m, typ="distance", key=("threat", "A1", "distance"), friendly=False)
    assert v.judge([d(100, 1.3)]) == []                           # not 1.4x closer than at contact
    assert len(v.judge([d(110, 1.5)])) == 1


def test_merge_for_common_parent():
    v = voa()
    a = cand(0, 1, typ="contact", key=1, group=("prox", "C"))
    b = cand(0, 1, typ="contact", key=2, group=("prox", "C"))
    c = cand(0, 1, typ="contact", key=3, group=("prox", "B"))
    out = v.merge(v.judge([a, b, c]))
    assert [x.type for x in out] == ["proximity", "contact"]
    assert v.stats["merged"] == 1


def test_voa_off_passes_everything():
    v = Voa(load_config(), enabled=False)
    assert len(v.judge([cand(0, 1), cand(1, 1), cand(2, 1)])) == 3


def test_histories_per_unit_place_and_forgetting():
    v = voa()
    v.remember(10, "monitored", ["H1"], places=["NAI-1"], cells=["3:4"])
    assert v.by_scope[("place", "NAI-1")] == [(10, "monitored")]
    assert v.by_scope[("cell", "3:4")] and v.by_scope[("unit", "H1")]
    v.judge([cand(10, 1)])
    v.forget_before(10 + 721)
    assert not v.history and not v.by_scope


def test_per_ea_override(tmp_path):
    p = tmp_path / "ea.toml"
    base = (load_config.__globals__["DEFAULT_PATH"]).read_text()
    p.write_text(base + "\n[ea.A2.voi]\nout_of_position_m = 90.0\n")
    assert load_config(p, "A2")["voi"]["out_of_position_m"] == 90.0
    assert load_config(p, "A1")["voi"]["out_of_position_m"] == 150.0


def test_a_projection_and_its_violation_are_one_story():
    """A projected violation sets the actual alert's history: the actual is dropped unless
    the repeat ratio is crossed, and then told at its own priority with when it was foretold."""
    v = voa()
    p = Candidate(100, "projected-out-of-position", "priority", ("A1",), "will leave", key=("p", "A1"),
                  measure=50.0, also=((("oop", "A1"), 150.0),), projection=True)
    assert len(v.judge([p])) == 1
    assert v.judge([cand(130, 200)]) == [] and v.stats["suppressed-projected"] == 1   # within ratio 2 x 150
    [late] = v.judge([cand(140, 320)])                      # twice the threshold: told, not as a repeat
    assert late.priority == "immediate" and not late.repeat and late.details["projected_at_t"] == 100
    assert v.judge([cand(400, 500)]) == []                  # now an ordinary history: 2 x 320 needed
    w = voa()   # without the projection flag the same `also` is an ordinary baseline (a repeat, lowered)
    w.judge([Candidate(100, "contact", "flash", ("A1",), "c", key=("c",), also=((("oop", "A1"), 150.0),))])
    [rep] = w.judge([cand(400, 320)])
    assert rep.repeat and rep.priority == "priority"


def test_projection_settings_are_checked():
    import pytest
    from ea_agent.core.config import ConfigError
    with pytest.raises(ConfigError, match="field 'projection_trend_s': must be > 0"):
        load_config(overrides={"voi": {"projection_trend_s": 0}})
    assert load_config(overrides={"voi": {"projection_horizon_s": 0}})["voi"]["projection_horizon_s"] == 0   # off
