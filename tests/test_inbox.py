"""Blocking instead of polling (`saim_mesh/inbox.py`): a `Waker` wakes on what an
`Inbox` takes from Zenoh, an inbox keeps order and bounds itself, a store query through
one is answered by a loop that sleeps between queries, and a replay waiting for its
peers sleeps instead of spinning a CPU."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest
import zenoh

from saim_mesh.inbox import Inbox, Waker
from saim_mesh.proc import Proc
from saim_mesh.zconf import config, free_port

ROOT = Path(__file__).resolve().parents[1]


def test_a_wake_before_or_during_the_wait_is_not_lost_and_many_count_once():
    w = Waker()
    assert w.wait(0.01) is False
    w.wake()   # before the wait: the wait returns at once
    assert w.wait(5.0) is True
    threading.Timer(0.05, w.wake).start()   # during the wait
    assert w.wait(5.0) is True
    for _ in range(5):
        w.wake()
    assert w.wait(5.0) is True
    assert w.wait(0.0) is False   # the five were taken by one wait


def test_an_inbox_keeps_order_wakes_its_waker_and_drops_past_its_bound():
    w = Waker()
    box = Inbox(w, cap=3)
    assert box.try_recv() is None
    for x in "abcd":
        box(x)
    assert box.dropped == 1
    assert w.wait(0.0) is True
    assert [box.try_recv() for _ in range(4)] == ["a", "b", "c", None]


@pytest.mark.timeout(60)
def test_a_query_through_an_inbox_is_answered_by_a_loop_that_sleeps():
    ep = f"tcp/127.0.0.1:{free_port()}"
    w = Waker()
    with zenoh.open(config([ep], [])) as a, zenoh.open(config([], [ep])) as b:
        box = Inbox(w, 8)
        box.decl = a.declare_queryable("inbox/store", box)
        sub_box = Inbox(w, 8)
        sub_box.decl = a.declare_subscriber("inbox/data", sub_box)
        got: list = []

        def ask():
            # ask once the queryable is known across the link (a get before that is answered
            # by nobody at once: a hundred of those went by before it was known on a loaded
            # machine); then until answered, as a reply can still miss a short timeout
            querier = b.declare_querier("inbox/store", timeout=2.0)
            known = threading.Event()
            listener = querier.declare_matching_listener(lambda st: known.set() if st.matching else None)
            if querier.matching_status.matching:
                known.set()
            if known.wait(20.0):
                for _ in range(10):
                    replies = [r.ok.payload.to_bytes() for r in querier.get() if r.ok is not None]
                    if replies:
                        got.extend(replies)
                        b.put("inbox/data", b"done")
                        break
            listener.undeclare()
            querier.undeclare()
        th = threading.Thread(target=ask)
        th.start()
        wakes = 0
        end = time.monotonic() + 30
        data = None
        while data is None and time.monotonic() < end:
            if w.wait(1.0):
                wakes += 1
            while (q := box.try_recv()) is not None:
                q.reply("inbox/store", b"answer")
                del q
            data = sub_box.try_recv()
        th.join(10)
        # the sample's wake is taken by a later wait, or, when the sample came while the
        # loop was still answering the query (it then read both in one pass), still pending
        sample_woke = wakes >= 2 or w.wait(0.0)
    assert got == [b"answer"] and data is not None and data.payload.to_bytes() == b"done"
    assert wakes >= 1 and sample_woke   # a query and a sample, each woke the loop


def _cpu_s(pid: int) -> float:
    f = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="CPU time from /proc")
@pytest.mark.timeout(120)
def test_a_replay_waiting_for_its_peers_sleeps_instead_of_spinning(tmp_path):
    """Waiting for a peer to come, then for one that never acks (the pacer): the
    replay's CPU over two seconds of each is a small part of a CPU (it used to poll
    every half millisecond, and spin on liveliness queries while peers were starting)."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    root = f"inbox/{uuid.uuid4().hex[:8]}"
    rp = Proc("replay", [sys.executable, "-m", "saim_mesh", "replay", str(ROOT / "scenarios" / "small"),
                         "--listen", ep, "--root", root, "--speed", "max", "--wait-peers", "A", "--linger", "0"],
              log_dir=tmp_path)
    try:
        rp.wait_for("ready", 60)
        c0 = _cpu_s(rp.p.pid)
        time.sleep(2.0)   # the span measured, not a synchronisation
        waiting_for_peer = _cpu_s(rp.p.pid) - c0
        with zenoh.open(config([], [ep])) as s:
            token = s.liveliness().declare_token(f"{root}/alive/A/fakezid")   # a peer that never acks
            rp.wait_for("start", 30)
            c1 = _cpu_s(rp.p.pid)
            time.sleep(2.0)
            pacing = _cpu_s(rp.p.pid) - c1
            assert rp.p.poll() is None
            token.undeclare()
    finally:
        rp.stop()
    assert waiting_for_peer < 0.5, waiting_for_peer
    assert pacing < 0.5, pacing
    assert not any("Traceback" in x for x in rp.tail(50)), json.dumps(rp.tail(50))
