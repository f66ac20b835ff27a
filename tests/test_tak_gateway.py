"""The Cursor-on-Target gateway (saim_mesh/tak/): its mesh-independent core driven by
in-process EAs, PLI in from pytak-made events, the pytak transports on loopback, and the
gateway as a mesh peer sending to a local multicast group and a local TCP receiver.

Loopback only: multicast goes out on 127.0.0.1 with TTL 0 (IP_MULTICAST_IF), free ports
at run time, every child reaped, waits on events and conditions, never on sleeps."""
from __future__ import annotations

import asyncio
import json
import socket
import sys
import threading
import warnings
from configparser import ConfigParser
from datetime import datetime, timedelta, timezone
from urllib.parse import urlparse

import pytest
import takproto

from saim_mesh.protocol import messages as M
from saim_mesh import scenario as S
from saim_mesh.protocol import wire as W
from saim_mesh.launch.proc import clean_env
from saim_mesh.inprocess.runner import config_for, make_ea
from saim_mesh.tak import cot as C
from saim_mesh.tak import types as T
from saim_mesh.tak.gateway import LiveTakFeed
from saim_mesh.tak.picture import Options, Picture
from saim_mesh.tak.pli import PliIn, UidMap, load_uids
from saim_mesh.tak.transports import Network
from saim_mesh.launch.zenoh_config import free_port

from .conftest import ROOT, SMALL

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import pytak

pytestmark = pytest.mark.timeout(120)
EPOCH = datetime(2026, 5, 1, 6, 0, 0, tzinfo=timezone.utc)
GROUP = "239.255.42.99"      # organisation-local; sent on 127.0.0.1 with TTL 0: never leaves the host


def cot_alert(b: bytes) -> dict | None:
    """The alert a CoT event carries, as the EA's JSON has it (None: not an alert)."""
    ev = C.parse(b)
    s = ev.detail.get("__saim", {})
    if s.get("kind") != "alert":
        return None
    head = f"[{s['priority'].upper()}] {s['owner']} "
    assert ev.remarks.startswith(head)
    msg = ev.remarks.split(f" {s['type']}: ", 1)[1]
    return {"id": s["id"], "owner": s["owner"], "type": s["type"], "priority": s["priority"],
            "category": s["category"], "subjects": json.loads(s["subjects"]), "message": msg,
            "t": round(float(s["t"]), 3)}


def tcp_plan_alerts(got) -> list[dict]:
    """The plan's alerts a TAK server took over TCP (not the wall clock's `/w` ones), sorted
    as `ea_alert`s are, to compare with the EAs' own logs."""
    return sorted((a for s, d in got if s == "tcp" for a in [cot_alert(d)] if a is not None
                   and a["id"] and "/w" not in a["id"]), key=json.dumps)


def every_ea_alert_on_tak(rx, logs) -> list[dict]:
    """The plan alerts the EAs logged (`logs`: their alert logs), each of them on the TAK
    server over TCP and none besides, within 30 s of the EAs' end; returned, sorted."""
    want = sorted((ea_alert(json.loads(x)) for f in logs for x in open(f)
                   if json.loads(x)["category"] != "system-problem"), key=json.dumps)
    assert len(want) >= 5

    def alerts():
        return tcp_plan_alerts(rx.got)
    assert rx.wait(lambda g: len(alerts()) >= len(want), 30), (len(alerts()), len(want))
    assert alerts() == want
    return want


def ea_alert(a: dict) -> dict:
    return {"id": a["details"].get("id", ""), "owner": a["owner"], "type": a["type"], "priority": a["priority"],
            "category": a["category"], "subjects": list(a["subjects"]), "message": a["message"],
            "t": round(a["t"], 3)}


# -- the core, in process --------------------------------------------------------------
def test_an_acknowledged_emergency_is_cancelled_on_tak(small):
    """A flash alert is an emergency on TAK; a re-notification (notice/A/A) sends the same
    uid again, never a new marker; once its EA takes an acknowledgement (heard on
    cmdlog/<owner>), the gateway cancels it once (b-a-o-can, same uid) and nothing else; a
    refused ack, an ack of a marker alert or of another EA's alert cancels nothing; a
    silenced or inhibited alert never reaches TAK users."""
    sent: list[bytes] = []
    pic = Picture(small, Options(epoch=EPOCH))
    feed = LiveTakFeed(small, None, "saim", pic, sent.append, overlay_every=None, log=lambda *a, **k: None)
    flash = M.Alert(100.0, "A", "fratricide", "friendly-activity", "flash", ("A1", "B1"), "A1 and B1 close",
                    {"id": "A/1"})
    other = M.Alert(110.0, "A", "out-of-position", "plan-constraint-violated", "immediate", ("A2",), "A2 off",
                    {"id": "A/3"})
    quiet = [M.Alert(120.0, "A", "contact", "adversarial-activity", "flash", ("A2",), "contact", {"id": "A/4",
                     "silenced": "s1"}),
             M.Alert(121.0, "A", "distance", "adversarial-activity", "immediate", ("A2",), "near",
                     {"id": "A/5", "inhibited_by": {"rule": "r", "source": "A/4"}})]
    for a in (flash, other, *quiet):
        feed.take(f"saim/alert/A/{a.type}", M.encode(a))
    assert feed.view.alerts == 4 and feed.view.quiet == 2

    def notice(alert, owner="A", kind="renotify", to="A"):
        return W.encode(W.make(W.Notice, kind=kind, t=220.0, owner=owner, alert=alert, story=alert, type="fratricide",
                               priority="flash", subjects=["A1", "B1"], message="A1 and B1 close", count=1, to=to,
                               due_t=100.0))
    feed.take("saim/notice/A/A", notice("A/1"))
    feed.take("saim/notice/A/A", notice("A/99"))            # never seen: nothing to re-send
    feed.take("saim/notice/B/A", notice("A/1", kind="escalate", to="B"))   # for the superior's console
    feed.take("saim/notice/A/B", notice("A/1", owner="A"))  # not B's alert: refused, counted (as the console does)
    assert feed.gate.rejects.total == 1
    uids = [C.parse(b).uid for b in sent]
    assert [C.parse(b).type for b in sent] == [T.EMERGENCY, T.MARKER, T.EMERGENCY] and uids[2] == uids[0]
    ack = lambda ref, ok=True, unit="A": W.encode(W.make(W.CmdResult, req="r", kind="ack", ok=ok, t=140.0,  # noqa: E731
                                                          ref=ref))
    for payload, key in [(ack("A/1", ok=False), "saim/cmdlog/A"), (ack("A/3"), "saim/cmdlog/A"),
                         (ack("A/1"), "saim/cmdlog/B"), (b"\x00junk", "saim/cmdlog/A")]:
        feed.take(key, payload)
    assert len(sent) == 3 and feed.gate.rejects.total == 3   # + another EA's alert; junk
    feed.take("saim/cmdlog/A", ack("A/1"))
    cancels = [C.parse(b) for b in sent[3:]]
    assert [c.type for c in cancels] == [T.CANCEL] and [c.uid for c in cancels] == uids[:1]
    for c, b in zip(cancels, sent[3:]):
        assert c.detail["emergency"]["cancel"] == "true" and c.detail["__saim"]["id"] == "A/1"
        assert c.time == EPOCH + timedelta(seconds=140.0) and c.stale > c.start >= c.time
        assert takproto.parse_proto(takproto.xml2proto(b)) is not None
    feed.take("saim/cmdlog/A", ack("A/1"))   # once only
    feed.take("saim/notice/A/A", notice("A/1"))   # acknowledged: nothing to re-send
    assert len(sent) == 4 and pic.counts["cancel"] == 1


def test_positions_go_out_per_period_and_only_when_changed(small):
    pic = Picture(small, Options(period_s=10.0, refresh_s=60.0, epoch=EPOCH))
    reps = [e for e in small.events if type(e) is M.LocationReport][:50]
    for r in reps:
        pic.message(r)
    first = pic.due(5.0)
    assert first and pic.due(9.0) == []                 # within the period: nothing
    assert pic.due(15.0) == []                          # nothing moved
    moved = M.LocationReport(16.0, reps[0].entity, reps[0].lon + 0.01, reps[0].lat)
    pic.message(moved)
    again = pic.due(25.0)
    changed = {C.parse(b).detail["__saim"]["unit"] for b in again}
    u = small.taskorg.entity_unit[reps[0].entity]
    assert u in changed and changed <= {u, *small.taskorg.ancestors(u)}
    assert len(pic.due(70.0)) == len(first) - len(again)   # the refresh: all not sent for 60 s


def test_inprocess_eas_alerts_become_cot_with_the_same_content(small):
    pic = Picture(small, Options(epoch=EPOCH))
    sent: list[bytes] = []
    eas = [make_ea(small, o, config_for(small, o), sinks=[lambda a: sent.append(pic.alert_event(a))])
           for o in ("A", "A2")]
    for ea in eas:
        ea.start(0.0)
    for ev in small.events:
        if ev.t > 2400:
            break
        pic.message(ev)
        for ea in eas:
            ea.submit(ev)
    for ea in eas:
        ea.finish(2400.0)
    want = [ea_alert(json.loads(json.dumps(a.to_json_dict()))) for ea in eas for a in ea.alerts]
    got = [cot_alert(b) for b in sent]
    assert len(want) >= 5
    assert sorted(got, key=json.dumps) == sorted(want, key=json.dumps)
    flash = [C.parse(b) for b in sent if C.parse(b).detail["__saim"]["priority"] == "flash"]
    assert all(ev.type in T.EMERGENCY_NAMES for ev in flash)
    for b in sent:   # every alert is placed where its subjects are (inside the scenario's area)
        ev = C.parse(b)
        assert 34.5 < ev.lat < 36 and -117.5 < ev.lon < -116


# -- PLI in ----------------------------------------------------------------------------
def pli(uid: str, lon: float, lat: float, callsign: str | None = None, stale: int = 120) -> bytes:
    """A TAK client's position report as pytak makes it."""
    return pytak.gen_cot(lat=lat, lon=lon, ce=10, hae=0, le=10, uid=uid, stale=stale, cot_type="a-f-G-U-C",
                         callsign=callsign)


def test_uid_map_file_and_rules(small, tmp_path):
    ex = load_uids(ROOT / "configs" / "tak-uids.example.toml")
    ex.check(set(small.taskorg.entity_unit))
    assert ex.uids and ex.rule
    j = tmp_path / "uids.json"
    j.write_text(json.dumps({"uids": {"ANDROID-x": "A2S1E01"}, "rule": "callsign"}))
    m = load_uids(j)
    p = PliIn(small, m)
    assert p.take(pli("ANDROID-x", -116.6, 35.2), 5.0).entity == "A2S1E01"
    assert p.take(pli("ANDROID-y", -116.6, 35.2, callsign="B1S1E02"), 5.0).entity == "B1S1E02"
    assert p.take(pli("ANDROID-z", -116.6, 35.2, callsign="NOBODY"), 5.0) is None
    assert p.rejects == {"unknown-entity": 1}
    rx = PliIn(small, UidMap({}, r"regex:^SAIM-(?P<entity>\w+)$"))
    assert rx.take(pli("SAIM-C1S2E01", -116.6, 35.2), 5.0).entity == "C1S2E01"
    assert rx.take(pli("ANDROID-q", -116.6, 35.2), 5.0) is None and rx.rejects == {"unknown-uid": 1}
    assert PliIn(small, UidMap({}, "uid")).take(pli("A1S1E01", -116.6, 35.2), 5.0).entity == "A1S1E01"
    for bad in ("nonsense", "regex:(", "regex:nogroup"):
        with pytest.raises(ValueError, match="uid rule"):
            UidMap({}, bad)
    with pytest.raises(ValueError, match="cannot read"):
        load_uids(tmp_path / "missing.toml")


def test_pli_skips_own_and_non_pli_and_refuses_stale(small):
    p = PliIn(small, UidMap({}, "uid"), own="saim.")
    assert p.take(pli("saim.x.unit.A", -116.6, 35.2), 1.0) is None
    chat = pytak.gen_cot(lat=35.2, lon=-116.6, uid="A1S1E01", cot_type="b-t-f")
    assert p.take(chat, 1.0) is None
    assert p.skipped == {"own": 1, "not-pli": 1} and p.rejected == 0
    t = datetime.now(timezone.utc) - timedelta(minutes=10)
    old = C.event("A1S1E01", "a-f-G-U-C", -116.6, 35.2, t, t + timedelta(minutes=2))
    assert p.take(old, 1.0) is None and p.rejects == {"stale": 1}
    assert p.take(b"\xbf\x05\x01", 1.0) is None and p.rejects["malformed"] == 1


def test_pli_from_pytak_makes_the_ea_alert(small):
    """A person with ATAK is entity A2S1E01: their reports replace the scenario's for that
    entity; 10 km away from their platoon, the EA alerts that the platoon is out of position."""
    gate = PliIn(small, UidMap({"ANDROID-alpha": "A2S1E01"}))

    def run(with_pli: bool):
        ea = make_ea(small, "A2", config_for(small, "A2"))
        ea.start(0.0)
        last = -1e9
        for ev in small.events:
            if ev.t > 900:
                break
            if with_pli and type(ev) is M.LocationReport and ev.entity == "A2S1E01":
                if ev.t - last >= 5.0:
                    last = ev.t
                    rep = gate.take(pli("ANDROID-alpha", ev.lon - 0.1, ev.lat + 0.05, "ALPHA"), ev.t)
                    assert rep is not None, gate.last_error
                    ea.submit(rep)
                continue
            ea.submit(ev)
        ea.finish(900.0)
        return [a for a in ea.alerts if a.type == "out-of-position" and "A2" in a.subjects]

    base, moved = run(False), run(True)
    assert gate.accepted >= 10 and gate.rejected == 0
    new = [a for a in moved if (a.t, a.message) not in {(b.t, b.message) for b in base}]
    assert new, "no out-of-position alert caused by the PLI"


# -- transports on loopback, receivers and senders built with pytak ----------------------
def _cfg(**kw) -> object:
    cp = ConfigParser(interpolation=None)
    cp["t"] = {k: str(v) for k, v in kw.items()}
    return cp["t"]


class Receivers:
    """A TCP server and a multicast member, both reading with pytak's RXWorker, on their
    own asyncio loop; events are kept raw (XML or TAK protocol v1 mesh) with their source."""

    def __init__(self, tcp_port: int, group: str, mport: int):
        self.tcp_port, self.group, self.mport = tcp_port, group, mport
        self.got: list[tuple[str, bytes]] = []
        self.cond = threading.Condition()
        self.ready = threading.Event()
        self.loop = asyncio.new_event_loop()
        self.tasks: list = []
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        assert self.ready.wait(20)

    def _add(self, src: str, data: bytes) -> None:
        with self.cond:
            self.got.append((src, bytes(data)))
            self.cond.notify_all()

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_until_complete(self._setup())
        self.ready.set()
        self.loop.run_forever()

    async def _setup(self) -> None:
        cfg = _cfg(TAK_PROTO=0)

        async def serve(reader, writer):
            """XML with pytak's reader (events end at </event>); TAK protocol v1 stream
            framing (0xbf, varint length) read here, since pytak's reader splits XML only."""
            rx = pytak.RXWorker(asyncio.Queue(), cfg, reader)
            try:
                while first := await reader.read(1):
                    if first[0] == C.STREAM:
                        head = first
                        while (b := await reader.readexactly(1))[0] & 0x80:
                            head += b
                        head += b
                        n = sum((x & 0x7F) << (7 * i) for i, x in enumerate(head[1:]))
                        data = head + await reader.readexactly(n)
                    elif (rest := await rx.readcot()) is None:
                        break
                    else:
                        data = first + rest
                    self._add("tcp", data)
            except (asyncio.IncompleteReadError, ConnectionError):
                pass
            writer.close()
        self.server = await asyncio.start_server(serve, "127.0.0.1", self.tcp_port, limit=1 << 20)
        reader, _ = await pytak.create_udp_client(urlparse(f"udp+ro://{self.group}:{self.mport}"), ("127.0.0.1", 0), 0)
        reader.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self.mreader = reader

        async def members():
            rx = pytak.RXWorker(asyncio.Queue(), cfg, reader)
            while True:
                data = await rx.readcot()
                if data:
                    self._add("udp", data)
        self.tasks.append(asyncio.ensure_future(members()))

    def wait(self, pred, timeout: float = 30.0) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: pred(self.got), timeout)

    def close(self) -> None:
        async def stop():
            self.server.close()
            for t in self.tasks:
                t.cancel()
            self.mreader.close()
        asyncio.run_coroutine_threadsafe(stop(), self.loop).result(10)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)


@pytest.mark.parametrize("proto", ["xml", "1"])
def test_network_sends_to_multicast_and_tcp_with_pytak(proto):
    tport, mport = free_port(), free_port()
    rx = Receivers(tport, GROUP, mport)
    net = Network([f"tcp://127.0.0.1:{tport}", f"udp://{GROUP}:{mport}"], proto, mcast_if="127.0.0.1", ttl=0)
    try:
        net.start()
        assert net.wait_connected(20)
        t = datetime.now(timezone.utc)
        evs = [C.event(f"u{i}", T.FRIENDLY_UNIT, -116.5 + i / 1000, 35.2, t, t + timedelta(minutes=5), callsign=f"C{i}")
               for i in range(50)]
        for e in evs:
            net.send(e)
        assert net.flush(20)
        assert rx.wait(lambda g: sum(s == "tcp" for s, _ in g) >= 50 and sum(s == "udp" for s, _ in g) >= 50)
    finally:
        net.close()
        rx.close()
    for src, data in rx.got:
        if proto == "1":   # TAK protocol v1: mesh framing on multicast, stream framing on TCP
            assert data[:3] == C.MESH if src == "udp" else data[0] == C.STREAM
            assert takproto.parse_proto(bytearray(data)).cotEvent.type == T.FRIENDLY_UNIT
    by = {src: sorted(C.parse(d).uid for s, d in rx.got if s == src) for src in ("tcp", "udp")}
    assert by["tcp"] == by["udp"] == sorted(f"u{i}" for i in range(50))
    assert all(s.n.sent == 50 and s.n.dropped == 0 for s in net.senders)


def test_network_listens_for_pli_and_survives_bad_input():
    lt, lu = free_port(), free_port()
    got: list[bytes] = []
    cond = threading.Condition()

    def on_data(data, src):
        with cond:
            got.append(data)
            cond.notify_all()
    net = Network([], listen=[f"tcp://127.0.0.1:{lt}", f"udp://127.0.0.1:{lu}"], on_data=on_data, max_bytes=4096)
    net.start()
    try:
        good = pli("ANDROID-1", -116.6, 35.2)

        async def send():
            for url in (f"tcp://127.0.0.1:{lt}", f"udp+wo://127.0.0.1:{lu}"):
                q: asyncio.Queue = asyncio.Queue()
                tx = await pytak.txworker_factory(q, _cfg(COT_URL=url, TAK_PROTO=0))
                await tx.send_data(good)
                await tx.send_data(C.encode(good, "stream" if url.startswith("tcp") else "mesh"))
                if url.startswith("tcp"):
                    await tx.send_data(b"<event>" + b"x" * 5000 + b"</event>")   # oversized: connection closed
                tx.writer.close()
        asyncio.run(asyncio.wait_for(send(), 20))
        with cond:
            assert cond.wait_for(lambda: len(got) >= 4, 20)
        for data in got:
            assert C.parse(data).uid == "ANDROID-1"
        assert net.oversized == 1
        s = socket.create_connection(("127.0.0.1", lt))   # the listener still takes new connections
        s.sendall(good)
        with cond:
            assert cond.wait_for(lambda: len(got) >= 5, 20)
        s.close()
    finally:
        net.close()


# -- the gateway on the mesh -------------------------------------------------------------
def _gateway_cmd() -> list[str]:
    """`saim-mesh tak`."""
    return [sys.executable, "-m", "saim_mesh", "tak"]


# -- through a real TAK server -----------------------------------------------------------
FTS_PYTHON = __import__("os").environ.get("SAIM_FTS_PYTHON")   # a python with FreeTAKServer (docs/tak.md)


@pytest.mark.timeout(240)
@pytest.mark.skipif(not FTS_PYTHON, reason="SAIM_FTS_PYTHON (a venv with FreeTAKServer 2.2.1) not set: docs/tak.md")
def test_events_reach_a_tak_client_through_freetakserver(tmp_path):
    """The gateway's TCP sender -> FreeTAKServer's CoT port -> another TCP client (an ATAK stand-in)."""
    import os
    import signal
    import subprocess
    ports = {k: free_port() for k in ("CoT", "SSLCoT", "DataPackage", "SSLDataPackage", "RestAPI")}
    args = [a for k, p in ports.items() for a in (f"-{k}IP", "127.0.0.1", f"-{k}Port", str(p))]
    env = {**clean_env(), "FTS_FIRST_START": "false", "HOME": str(tmp_path)}
    log = open(tmp_path / "fts.log", "wb")
    fts = subprocess.Popen([FTS_PYTHON, "-m", "FreeTAKServer.controllers.services.FTS", *args, "-AutoStart", "True"],
                           stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env, cwd=tmp_path,
                           start_new_session=True)
    net = None
    try:
        client = None
        for _ in range(600):   # FTS starts its services in about 20 s: retry the connection, bounded
            if fts.poll() is not None:
                pytest.fail(f"FreeTAKServer exited ({fts.returncode}): {(tmp_path / 'fts.log').read_text()[-800:]}")
            try:
                client = socket.create_connection(("127.0.0.1", ports["CoT"]), timeout=0.2)
                break
            except OSError:
                threading.Event().wait(0.1)
        assert client is not None, "FreeTAKServer's CoT port never opened"
        client.settimeout(30)
        client.sendall(pli("ANDROID-watcher", -116.6, 35.2, "WATCHER"))
        heard = threading.Event()   # the server's welcome to the gateway: it is registered
        net = Network([f"tcp://127.0.0.1:{ports['CoT']}"], "xml", on_data=lambda d, s: heard.set(),
                      hello=Picture(S.load(SMALL, events=False)).presence_event())
        net.start()
        assert net.wait_connected(30) and heard.wait(60)
        t = datetime.now(timezone.utc)
        net.send(C.event("saim.test.unit.A2", T.FRIENDLY_UNIT, -116.55, 35.25, t, t + timedelta(minutes=5),
                         callsign="2 PLT, A CO"))
        assert net.flush(20)
        got = b""
        while b"saim.test.unit.A2" not in got:
            chunk = client.recv(65536)
            assert chunk, "FreeTAKServer closed the client's connection"
            got += chunk
        start = got.rindex(b"<event", 0, got.index(b"saim.test.unit.A2"))
        ev = C.parse(got[start:].split(b"</event>")[0] + b"</event>")
        assert ev.callsign == "2 PLT, A CO" and ev.type == T.FRIENDLY_UNIT
        client.close()
    finally:
        if net is not None:
            net.close(0)
        os.killpg(fts.pid, signal.SIGTERM)   # FTS and the service processes it started (its own group)
        try:
            fts.wait(20)
        except subprocess.TimeoutExpired:
            os.killpg(fts.pid, signal.SIGKILL)
            fts.wait()
        log.close()
