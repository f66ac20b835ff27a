"""The live console and the live TAK gateway stand on `live.reader.LiveReader` alone
(issue 51.3): every payload checked by the gate and against its key, the picture and the
clock from the sources' frames, and nothing of the replay mesh imported, neither by the
modules nor by a console or gateway started on the live mesh."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from saim_mesh.protocol import messages as M
from saim_mesh.protocol import wire as W
from saim_mesh.console.feed import live_feed
from saim_mesh.console.state import State
from saim_mesh.live import frames as F
from saim_mesh.tak.gateway import LiveTakFeed
from saim_mesh.tak.picture import Options, Picture
from saim_mesh.launch.zenoh_config import free_port

from .conftest import ROOT, SMALL

# issue 51: the replay mesh's modules, to be deleted; the live path must not load them
REPLAY = ["peer", "replay", "intake", "tickwait", "store", "storeq", "inbox", "batch", "keyfacts", "radios",
          "script", "presence", "offline", "fusion.peer", "fusion.barrier", "reader"]
QUIET = lambda *a, **k: None   # noqa: E731


def frame(source: str, seq: int, wm: float, msgs: list, end: bool = False) -> bytes:
    return F.encode(F.Frame(v=1, source=source, epoch=1, seq=seq, wm=wm, msgs=[M.encode(m) for m in msgs], end=end))


def alert(owner: str = "A", n: int = 1) -> M.Alert:
    return M.Alert(100.0, owner, "out-of-position", "plan-constraint-violated", "immediate", (owner,), "off",
                   {"id": f"{owner}/{n}"})


def test_the_live_console_checks_every_payload(small):
    st = State(small)
    feed = live_feed(small, None, "saim", st, log=QUIET)
    assert set(feed.keys()) == {"saim/alert/**", "saim/cmdlog/*", "saim/notice/*/*", "saim/src/*/**"}
    ev = next(e for e in small.events if type(e) is M.LocationReport)
    feed.take("saim/src/cp.A", frame("cp.A", 1, 10.0, [ev]))
    assert st.t == 10.0 and not st.ended and st.entity_pos
    feed.take("saim/src/cp.B", frame("cp.A", 2, 50.0, [ev]))          # A's frame on B's key
    feed.take("saim/src/cp.A", b"\x00junk")
    feed.take("saim/ack/A/cp.A", W.encode(W.make(W.Ack, t=30.0)))   # a well-formed pace ack: not the feed's
    assert st.t == 10.0 and feed.gate.rejects.total == 3
    feed.take("saim/alert/A/out-of-position", M.encode(alert()))
    feed.take("saim/alert/B/out-of-position", M.encode(alert()))     # owner differs from the key
    feed.take("saim/alert/A/out-of-position", M.encode(ev))          # not an alert
    feed.take("saim/cmdlog/A", b"junk")
    assert st.known_alert("A/1") == "A" and len(st.alerts) == 1 and feed.gate.rejects.total == 6
    feed.take("saim/src/cp.A", frame("cp.A", 2, 20.0, [], end=True))
    assert st.t == 20.0 and st.ended   # every source heard has ended


def test_the_live_gateway_draws_frames_and_sends_alerts(small):
    from .test_tak_gateway import EPOCH
    sent: list[bytes] = []
    pic = Picture(small, Options(epoch=EPOCH))
    feed = LiveTakFeed(small, None, "saim", pic, sent.append, overlay_every=None, log=QUIET)
    feed.take("saim/alert/A/out-of-position", M.encode(alert()))
    assert len(sent) == 1 and feed.view.alerts == 1
    ev = next(e for e in small.events if type(e) is M.LocationReport)
    feed.take("saim/src/cp.A", frame("cp.A", 1, 10.0, [ev]))
    assert len(sent) > 1 and pic.t == 10.0   # the positions due at the frame's watermark
    feed.take("saim/src/cp.A", frame("cp.B", 2, 20.0, [ev]))
    feed.take("saim/notice/A/B", W.encode(W.make(W.Notice, kind="renotify", t=220.0, owner="A", alert="A/1",
                                                 story="A/1", type="out-of-position", priority="immediate",
                                                 subjects=["A"], message="off", count=1, to="A", due_t=100.0)))
    assert feed.gate.rejects.total == 2 and pic.t == 10.0


def loaded_replay(code: str) -> list[str]:
    """The replay modules in sys.modules after running `code` in a fresh interpreter."""
    check = (f"{code}\nimport sys, json\n"
             f"print(json.dumps([m for m in {REPLAY!r} if 'saim_mesh.' + m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", check], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_live_feeds_import_nothing_of_the_replay():
    assert loaded_replay("import saim_mesh.live.reader, saim_mesh.console.feed, saim_mesh.console.main, "
                         "saim_mesh.tak.gateway, saim_mesh.cli") == []


STARTED = """
import os, signal, sys, threading, time
from saim_mesh.cli import main

def stop():   # once the command has its SIGTERM handler (it is up), a few seconds up, then stop it
    while signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        time.sleep(0.1)
    time.sleep(3.0)
    os.kill(os.getpid(), signal.SIGTERM)

threading.Thread(target=stop, daemon=True).start()
rc = main({argv!r})
assert rc == 0, rc
"""


@pytest.mark.timeout(180)
@pytest.mark.parametrize("cmd", [
    ["console", "--port", "0", "--linger", "0"],
    ["tak", "--cot-url", "udp://127.0.0.1:{port}", "--no-overlay", "--linger", "0"],
])
def test_a_live_console_or_gateway_started_loads_nothing_of_the_replay(cmd):
    """`saim-mesh console|tak SCENARIO`, run a few seconds and stopped: the
    replay's modules were never loaded, at start, while serving, or when closing."""
    port = free_port()
    argv = [cmd[0], str(SMALL), *[x.format(port=free_port()) for x in cmd[1:]],
            "--listen", f"tcp/127.0.0.1:{port}"]
    assert loaded_replay(STARTED.format(argv=argv)) == []
