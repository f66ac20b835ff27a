"""A live EA's watch on its sources (`live/liveness.py`): who is silent past the limit, on
the wall clock handed in (no sleeping here)."""
from __future__ import annotations

from types import SimpleNamespace

from saim_mesh.live.liveness import SourceWatch


class Order:
    def __init__(self):
        self.lost: dict[str, str] = {}
        self.released = 0.0


def frame(source, wm, end=False):
    return SimpleNamespace(source=source, wm=wm, end=end)


def test_a_source_never_heard_waits_join_s_and_a_heard_one_silence_s():
    w = SourceWatch(["a", "b"], silence_s=10.0, join_s=30.0)
    w.took(frame("a", 4.0))
    o = Order()
    o.released = 4.0             # the EA took all `a` promised: now it holds the EA back
    t = w.heard["a"]
    w.started = t
    assert list(w.silent(t + 9.0, o)) == []
    assert list(w.silent(t + 11.0, o)) == [("a", "silent for 11 s")]
    assert list(w.silent(t + 31.0, o)) == [("a", "silent for 31 s"), ("b", "never heard in 31 s")]


def test_ended_lost_and_ahead_sources_are_never_called_silent():
    w = SourceWatch(["a", "b", "c"], silence_s=10.0, join_s=10.0)
    w.took(frame("a", 50.0, end=True))
    w.took(frame("b", 50.0))
    w.took(frame("c", 5.0))
    o = Order()
    o.released = 20.0            # b promised beyond it: it holds nothing back
    t = max(w.heard.values()) + 100.0
    assert list(w.silent(t, o)) == [("c", "silent for 100 s")]
    o.lost["c"] = "silent"
    assert list(w.silent(t, o)) == []
    assert w.all_ended(o.lost) is False
    w.took(frame("b", 60.0, end=True))
    assert w.all_ended(o.lost) is True and w.furthest() == [50.0, 60.0, 5.0]


def test_each_source_is_judged_against_the_order_as_it_is_then():
    """Declaring one source lost can release the EA past another's promise: that one is
    then silent in the same pass, not one check later."""
    w = SourceWatch(["a", "b"], silence_s=10.0, join_s=10.0)
    w.took(frame("a", 5.0))
    w.took(frame("b", 30.0))
    o = Order()
    o.released = 20.0
    t = max(w.heard.values()) + 60.0
    said = []
    for src, why in w.silent(t, o):
        said.append(src)
        o.lost[src] = why
        o.released = 40.0        # the loss of `a` released the EA past b's promise
    assert said == ["a", "b"]


def test_a_source_whose_frames_arrived_but_wait_in_the_peers_queue_is_not_silent():
    """Silence is the source's, not the EA's: frames that came (the subscriber's callback)
    while the EA was busy with a backlog keep the source alive though not yet taken."""
    w = SourceWatch(["a", "b"], silence_s=10.0, join_s=30.0)
    w.took(frame("a", 4.0))
    w.took(frame("b", 4.0))
    o = Order()
    o.released = 4.0
    t = max(w.heard.values())
    w.arrived("a", t + 8.0)     # a frame of `a` arrived, still in the queue
    assert list(w.silent(t + 12.0, o)) == [("b", "silent for 12 s")]
    assert list(w.silent(t + 19.0, o)) == [("a", "silent for 11 s"), ("b", "silent for 19 s")]


def test_a_lost_source_is_waited_for_end_wait_s_once_every_other_ended():
    """A link healed near the end still brings what it held: with the rest ended, the EA
    finishes only after `end_wait_s` of wall time, or as soon as the lost one ends too."""
    w = SourceWatch(["a", "b"], silence_s=10.0, join_s=10.0, end_wait_s=30.0)
    o = Order()
    o.lost["b"] = "silent"
    w.took(frame("a", 50.0))
    assert w.finished(o.lost, 100.0) is False and w.rest_ended is None
    w.took(frame("a", 60.0, end=True))
    assert w.finished(o.lost, 100.0) is False and w.rest_ended == 100.0
    assert w.finished(o.lost, 129.0) is False
    assert w.finished(o.lost, 130.0) is True
    del o.lost["b"]                  # back before the wait ran out: it is waited for to its end
    w2 = SourceWatch(["a", "b"], silence_s=10.0, join_s=10.0, end_wait_s=30.0)
    w2.took(frame("a", 60.0, end=True))
    assert w2.finished({"b": "silent"}, 100.0) is False
    assert w2.finished({}, 200.0) is False and w2.rest_ended is None
    w2.took(frame("b", 70.0, end=True))
    assert w2.finished({}, 200.0) is True
