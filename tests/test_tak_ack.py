"""ATAK closes the loop (issue 33.6): an alert acknowledged in ATAK (a GeoChat message
naming it, or a `y-a-w` reply to its CoT) acknowledges it on its EA, as the unit the ATAK
user's uid is mapped to; the EA's answer goes back to the user in GeoChat.

The GeoChat events here are built the way ATAK builds them (ATAK-CIV 4.6,
GeoChatService.bundleToCot/addSendDetails: type b-t-f, how h-g-i-g-o, uid
`GeoChat.<sender>.<conversation>.<message id>`, `__chat` with `chatgrp uid0=<sender>
uid1=<room or recipient>`, a p-p link to the sender, `remarks source="BAO.F.ATAK.<sender>"
to time`, stale a day on). Unit tests of the parsing, the uid -> unit mapping and the
authority check; then a live mesh in secure mode (replay, BN's and A's EA peers armed, the
gateway listening on TCP, its CoT to a TCP receiver): an ATAK user mapped to BN acknowledges
BN alerts (GeoChat and y-a-w), BN's EA logs the acks taken and stops re-notifying them while
it re-notifies one left alone; a user mapped to C acknowledging an A alert is refused and
counted; an unknown alert is refused by the EA and said so. Loopback only, free ports,
every child stopped in `finally`, waits on what the processes print or send, bounded."""
from __future__ import annotations

import json
import socket
import threading
import time
import uuid
from datetime import datetime, timedelta, timezone
from pathlib import Path

import pytest
import takproto

from saim_mesh.protocol import messages as M
from saim_mesh.protocol import wire as W
from saim_mesh.tak import acks as A
from saim_mesh.tak.ack_send import AckSender, chat_event
from saim_mesh.tak import cot as C
from saim_mesh.tak.picture import Options, Picture
from saim_mesh.tak.pli import PliIn, UidMap, load_uids

pytestmark = pytest.mark.timeout(120)
EPOCH = datetime(2026, 5, 1, 6, 0, 0, tzinfo=timezone.utc)
PREFIX = "saim.small"
BN_USER, C_USER, A2_USER = "ANDROID-0123456789abcdef", "ANDROID-c0ffee0000000000", "ANDROID-a2a2a2a2a2a2a2a2"


def geochat(sender: str, callsign: str, text: str, room: str = A.ALL_CHAT, conv: str | None = None,
            dest: str | None = None, at: datetime | None = None, message_id: str | None = None,
            link: str | None = None) -> bytes:
    """A GeoChat message as ATAK sends it (GeoChatService.bundleToCot + addSendDetails)."""
    import xml.etree.ElementTree as ET
    now = at or datetime.now(timezone.utc)
    conv = conv or room
    mid = message_id or str(uuid.uuid4())
    chat = ET.Element("__chat", {"parent": "RootContactGroup", "groupOwner": "false", "messageId": mid,
                                 "chatroom": room, "id": conv, "senderCallsign": callsign})
    ET.SubElement(chat, "chatgrp", {"uid0": sender, "uid1": dest or conv, "id": conv})
    rm = ET.Element("remarks", {"source": f"BAO.F.ATAK.{sender}", "to": dest or conv, "time": C.iso(now)})
    rm.text = text
    det = [chat, ET.Element("link", {"uid": link or sender, "type": "a-f-G-U-C", "relation": "p-p"}),
           ET.Element("__serverdestination", {"destinations": f"192.168.1.7:4242:tcp:{sender}"}), rm]
    return C.event(f"GeoChat.{sender}.{conv}.{mid}", A.CHAT, -116.6, 35.2, now, now + timedelta(days=1),
                   how="h-g-i-g-o", detail=det)


def wilco(alert_uid: str, sender: str, callsign: str, typ: str = A.WILCO) -> bytes:
    """A CoT reply to the alert's event: same uid (as replies to a tasking), the sender's p-p link."""
    import xml.etree.ElementTree as ET
    now = datetime.now(timezone.utc)
    return C.event(alert_uid, typ, -116.6, 35.2, now, now + timedelta(minutes=1), how="h-e", callsign=callsign,
                   detail=[ET.Element("link", {"uid": sender, "type": "a-f-G-U-C", "relation": "p-p",
                                               "parent_callsign": callsign})])


def gate(sc, units=None, uids=None, rule=None, pic=None):
    pic = pic or Picture(sc, Options(epoch=EPOCH, uid_prefix=PREFIX))
    umap = UidMap(uids or {}, rule, units if units is not None else {BN_USER: "BN", C_USER: "C"})
    umap.check(set(sc.taskorg.entity_unit), set(sc.taskorg.units))
    lines: list[str] = []
    return A.AckIn(umap, pic.prefix, lambda: pic.taskorg, pic.alert_uids.get,
                   log=lambda *a, **k: lines.append(" ".join(map(str, a)))), pic, lines


def take(ack_in, data: bytes):
    return ack_in.take(C.parse(data))


# -- parsing: what ATAK sends ------------------------------------------------------------
def test_geochat_and_wilco_forms_name_alerts(small):
    g, pic, _ = gate(small)
    flash = M.Alert(100.0, "BN", "fratricide", "friendly-activity", "flash", ("A1", "B1"), "A1 and B1 close",
                    {"id": "BN/7"})
    ev = C.parse(pic.alert_event(flash))
    assert pic.alert_uids[ev.uid] == "BN/7" and ev.uid == f"{PREFIX}.alert.BN-7"
    cases = [("ack BN/3", ["BN/3"]), ("ACK: bn/3", ["BN/3"]), ("Acknowledged BN-3, BN/4 moving now", ["BN/3", "BN/4"]),
             (f"wilco {ev.uid}", ["BN/7"]), ("ack BN/w2", ["BN/w2"]), ("ack BN/3 BN/3", ["BN/3"]),
             ("ack A/2 at 12-30", ["A/2"]), ("ack BN/942.8f85", ["BN/942.8f85"]),
             ("ACK bn-w1200.0a1f.1, A/30.ffff", ["BN/w1200.0a1f.1", "A/30.ffff"]),
             (f"wilco {PREFIX}.alert.BN-942.8f85", ["BN/942.8f85"])]
    for text, want in cases:
        acks, replies = take(g, geochat(BN_USER, "BRAVO6", text))
        assert [a.alert for a in acks] == want and replies == [], text
        assert all(a.by == "BN" and a.uid == BN_USER and a.callsign == "BRAVO6" and a.form == "chat" for a in acks)
        assert acks[0].reply == A.Conversation(A.ALL_CHAT, A.ALL_CHAT, A.ALL_CHAT)   # answered in the room
    acks, _ = take(g, wilco(ev.uid, BN_USER, "BRAVO6"))
    assert [(a.alert, a.form, a.by) for a in acks] == [("BN/7", "wilco", "BN")]
    assert acks[0].reply == A.Conversation(BN_USER, "BRAVO6", BN_USER, "BRAVO6")   # a direct answer
    acks, _ = take(g, wilco(f"{PREFIX}.alert.BN-9", BN_USER, "BRAVO6", "y-a-w-d"))   # not remembered: by its shape
    assert [a.alert for a in acks] == ["BN/9"]
    # a direct message to the gateway, and one to the alert's own uid ("ack" alone names it)
    gw = f"{PREFIX}.gateway.cot"
    acks, _ = take(g, geochat(BN_USER, "BRAVO6", "ack BN/5", room="SAIM small", conv=gw, dest=gw))
    assert acks[0].alert == "BN/5" and acks[0].reply == A.Conversation(BN_USER, "BRAVO6", BN_USER, "BRAVO6")
    acks, _ = take(g, geochat(BN_USER, "BRAVO6", "ack", room="FLASH fratricide", conv=ev.uid, dest=ev.uid))
    assert [a.alert for a in acks] == ["BN/7"]
    # a team room: answered in that room
    acks, _ = take(g, geochat(BN_USER, "BRAVO6", "ack BN/6", room="Cyan", conv="Cyan"))
    assert acks[0].reply == A.Conversation("Cyan", "Cyan", "Cyan")
    # TAK protocol v1 (mesh and stream framing) carries the same detail
    for fmt in ("mesh", "stream"):
        b = C.encode(geochat(BN_USER, "BRAVO6", "ack BN/8"), fmt)
        assert takproto.parse_proto(bytearray(b)) is not None
        acks, _ = take(g, b)
        assert [a.alert for a in acks] == ["BN/8"], fmt
    assert g.asked == sum(len(w) for _, w in cases) + 7 and g.refused == {}   # the cases, then 7 one by one


def test_what_is_not_an_acknowledgement_is_skipped_not_answered(small):
    g, pic, lines = gate(small)
    t0 = datetime.now(timezone.utc)
    same = geochat(BN_USER, "BRAVO6", "ack BN/3", message_id="m-1")
    assert take(g, same)[0]
    gw = f"{PREFIX}.gateway.cot"
    ours = chat_event(gw, "SAIM small", A.Conversation(A.ALL_CHAT, A.ALL_CHAT, A.ALL_CHAT), "ACK BN/3: taken",
                        -116.6, 35.2)
    for data in [geochat(BN_USER, "BRAVO6", "moving to PL RED"),           # talk
                 geochat(BN_USER, "BRAVO6", "ack, moving"),                # talk that starts like an ack
                 geochat(BN_USER, "BRAVO6", "acknowledge receipt of the order"),
                 same,                                                     # heard again (multicast and server)
                 geochat(BN_USER, "BRAVO6", "ack BN/3", at=t0 - timedelta(hours=1)),   # a server's history
                 ours,                                                     # our own answer heard back
                 wilco(f"{PREFIX}.alert.BN-3", BN_USER, "BRAVO6", A.MACHINE_ACK),      # a machine receipt
                 wilco("ANDROID-someone.task.1", BN_USER, "BRAVO6"),      # someone else's tasking
                 geochat("", "NOBODY", "hello", link="")]:                 # no sender, not an ack either
        assert take(g, data) == ([], []), C.parse(data).remarks
    assert g.skipped == {"chat": 4, "duplicate": 1, "old": 1, "own": 1, "machine-ack": 1, "not-ours": 1}
    assert g.refused == {} and lines == [] and g.asked == 1
    # receipts (b-t-f-d/-r) and PLI are not for AckIn
    assert not g.wants(C.parse(C.event("GeoChat.x.y.z", "b-t-f-r", 0, 0, t0, t0 + timedelta(minutes=1))))
    assert not g.wants(C.parse(C.event(BN_USER, "a-f-G-U-C", 0, 0, t0, t0 + timedelta(minutes=1))))


def test_refusals_are_counted_said_in_one_line_and_answered(small):
    g, pic, lines = gate(small)
    cases = [  # (sender, text, reason, answer contains)
        ("ANDROID-stranger", "ack BN/3", "unknown-uid", "is not mapped to a unit"),
        (C_USER, "ack A/2", "authority", "acts for C, which does not command A (BN/A)"),
        (BN_USER, "ack X9/1", "unknown-owner", "X9 is not a unit"),
        (BN_USER, "ack " + " ".join(f"BN/{i}" for i in range(1, 10)), "too-many", "at most 8"),
    ]
    for sender, text, reason, said in cases:
        acks, replies = take(g, geochat(sender, "CALLSIGN", text))
        assert acks == [] and len(replies) == 1 and said in replies[0].text, (reason, replies)
        assert g.refused.get(reason) == 1, (reason, g.refused)
    # one refused, one taken from the same message: each alert on its own
    acks, replies = take(g, geochat(C_USER, "CHARLIE6", "ack C/1 A/2"))
    assert [a.alert for a in acks] == ["C/1"] and len(replies) == 1 and "A/2 refused" in replies[0].text
    # senders that disagree (a forged remarks source) and an unusable uid: refused, not fatal
    acks, replies = take(g, geochat(BN_USER, "BRAVO6", "ack BN/3", link=C_USER))
    assert acks == [] and replies == [] and g.refused["sender"] == 1
    acks, _ = take(g, geochat("X" * 150, "LONG", "ack BN/3"))
    assert acks == [] and g.refused["sender"] == 2
    assert take(g, wilco(f"{PREFIX}.alert.BN-3", "", "NOLINK")) == ([], []) and g.refused["sender"] == 3
    assert len(lines) == sum(g.refused.values()) == 8 and all(x.startswith("tak: ack refused (") for x in lines)


def test_the_mapped_unit_commands_the_owner_as_organized_now(small, tmp_path):
    """`[units]` maps a uid to the unit it acts for; a uid the `[uids]` table maps to an
    entity acts for that entity's unit; a rule gives no authority; a reorganization the
    gateway heard moves the authority with it."""
    f = tmp_path / "uids.toml"
    f.write_text(f'rule = "regex:^SAIM-(?P<entity>\\\\w+)$"\n[uids]\n"{A2_USER}" = "A2S1E01"\n'
                 f'[units]\n"{BN_USER}" = "BN"\n"ANDROID-alpha6" = "A"\n')
    umap = load_uids(f)
    assert umap.units == {BN_USER: "BN", "ANDROID-alpha6": "A"} and umap.uids == {A2_USER: "A2S1E01"}
    pic = Picture(small, Options(epoch=EPOCH, uid_prefix=PREFIX))
    g = A.AckIn(umap, PREFIX, lambda: pic.taskorg, pic.alert_uids.get, log=lambda *a, **k: None)
    assert [a.by for a in take(g, geochat(A2_USER, "ALPHA21", "ack A2S1/1"))[0]] == ["A2S1"]
    assert take(g, geochat(A2_USER, "ALPHA21", "ack A2/1"))[0] == []          # a squad does not command its platoon
    assert take(g, geochat("SAIM-A2S1E02", "ALPHA22", "ack A2S1/1"))[0] == []  # by rule: PLI only, no authority
    assert g.refused == {"authority": 1, "unknown-uid": 1}
    assert [a.by for a in take(g, geochat("ANDROID-alpha6", "ALPHA6", "ack R/1"))[0]] == ["A"]
    pic.message(M.Reorganization(600.0, "R", "BN"))   # R goes from A to BN
    assert take(g, geochat("ANDROID-alpha6", "ALPHA6", "ack R/2"))[0] == [] and g.refused["authority"] == 2
    assert [a.by for a in take(g, geochat(BN_USER, "BRAVO6", "ack R/2"))[0]] == ["BN"]
    # the file is checked at start; a commander's device reporting its position is not a monitored entity
    bad = tmp_path / "bad.toml"
    bad.write_text('[units]\n"ANDROID-x" = "NOPE"\n')
    with pytest.raises(ValueError, match="units not in the task organization: NOPE"):
        PliIn(small, load_uids(bad))
    bad.write_text('[units]\n"ANDROID-x" = 3\n')
    with pytest.raises(ValueError, match="field 'units'"):
        load_uids(bad)
    pli = PliIn(small, umap)
    from .test_tak_gateway import pli as pli_event
    assert pli.take(pli_event(BN_USER, -116.6, 35.2), 1.0) is None
    assert pli.skipped == {"commander": 1} and pli.rejected == 0
    assert pli.take(pli_event(A2_USER, -116.6, 35.2), 1.0).entity == "A2S1E01"


def test_answers_are_geochat_that_atak_files_in_the_conversation():
    gw = f"{PREFIX}.gateway.cot"
    room = chat_event(gw, "SAIM small", A.Conversation(A.ALL_CHAT, A.ALL_CHAT, A.ALL_CHAT), "ACK BN/3: taken",
                        -116.6, 35.2)
    dm = chat_event(gw, "SAIM small", A.Conversation(BN_USER, "BRAVO6", BN_USER, "BRAVO6"), "ACK BN/3: taken",
                      -116.6, 35.2)
    for b, dest in ((room, A.ALL_CHAT), (dm, BN_USER)):
        ev = C.parse(b)
        assert ev.type == A.CHAT and ev.uid.startswith(f"GeoChat.{gw}.") and ev.remarks == "ACK BN/3: taken"
        assert ev.detail["__chat/chatgrp"] == {"uid0": gw, "uid1": dest, "id": ev.detail["__chat"]["id"]}
        assert ev.detail["remarks"]["source"] == f"BAO.F.ATAK.{gw}" and A.chat_sender(ev) == gw
        assert ev.uid.endswith("." + ev.detail["__chat"]["messageId"])
        assert ev.stale - ev.time == timedelta(days=1)
        assert takproto.parse_proto(takproto.xml2proto(b)) is not None
    assert "marti" not in C.parse(room).detail
    assert C.parse(dm).detail["marti/dest"] == {"callsign": "BRAVO6"}


def test_the_sender_answers_every_outcome_and_never_dies():
    replies: list[tuple] = []
    lock = threading.Condition()

    def reply(conv, text):
        with lock:
            replies.append((conv, text))
            lock.notify_all()
    gone, entered = threading.Event(), threading.Event()

    def send(ack):
        if ack.alert == "BN/1":
            return W.make(W.CmdResult, req="r", kind="ack", ok=True, t=700.0, ref="BN/1")
        if ack.alert == "BN/2":
            return W.make(W.CmdResult, req="r", kind="ack", ok=False, t=700.0,
                          error="ack: unknown alert 'BN/2': not issued by the EA of BN (ids BN/1..BN/1)")
        if ack.alert == "BN/3":
            return W.make(W.CmdResult, req="r", kind="ack", ok=False, t=0.0,
                          error="no answer from the EA of BN within 10 s (not running, or access control refused)")
        if ack.alert == "BN/9":
            entered.set()
            gone.wait(20)   # an EA that takes its time: the queue fills behind it
            return W.make(W.CmdResult, req="r", kind="ack", ok=True, t=1.0, ref="BN/9")
        raise RuntimeError("boom")
    conv = A.Conversation(A.ALL_CHAT, A.ALL_CHAT, A.ALL_CHAT)
    mk = lambda aid: A.Ack(aid, "BN", "BN", BN_USER, "BRAVO6", "chat", conv)   # noqa: E731
    s = AckSender(send, reply, workers=1, max_pending=2, log=lambda *a, **k: None)
    try:
        for aid in ("BN/1", "BN/2", "BN/3", "BN/4"):
            assert s.submit(mk(aid))
            assert s.drain(10)
        texts = [t for _, t in replies]
        assert texts[0].startswith("ACK BN/1: taken by the EA of BN at H+00:11:40 (BRAVO6 as BN)")
        assert texts[1].startswith("ACK BN/2 refused by the EA of BN: ack: unknown alert")
        assert texts[2].startswith("ACK BN/3 not taken: no answer from the EA of BN")
        assert texts[3] == "ACK BN/4 not taken: RuntimeError: boom"
        assert s.outcomes == {"ok": 1, "refused-by-ea": 1, "no-answer": 1, "error": 1}
        assert s.submit(mk("BN/9")) and entered.wait(10)   # taken by the worker, which waits
        assert s.submit(mk("BN/9")) and s.submit(mk("BN/9"))   # queued (2 at most)
        assert not s.submit(mk("BN/9")) and s.busy == 1
        assert "refused: the gateway has 2 acknowledgements waiting" in replies[-1][1]
        gone.set()
        assert s.drain(20)
    finally:
        gone.set()
        s.close()
    assert all(not t.is_alive() for t in s.threads)


# -- the live mesh -----------------------------------------------------------------------
SPEED = 40        # scenario seconds per wall second: BN/3's first re-notification (t=966) is 7.5 s after it
UNTIL = 1500      # past the second re-notification of BN's immediate alerts of t=666-694 (every 300 s, twice)


def _notices(path: Path) -> list[dict]:
    try:
        return [json.loads(x) for x in open(path) if x.strip()]
    except FileNotFoundError:
        return []


def _cmdlog(path: Path) -> list[dict]:
    return _notices(path)


def _bounded(pred, timeout: float, what: str):
    """Poll a file-backed condition (what the peers wrote) until a deadline."""
    end = time.monotonic() + timeout
    while True:
        v = pred()
        if v:
            return v
        if time.monotonic() > end:
            raise AssertionError(f"within {timeout} s: {what}")
        time.sleep(0.05)


@pytest.mark.timeout(300)
def test_an_ack_from_atak_reaches_an_ea_on_the_live_mesh(tmp_path):
    """ATAK users acknowledge alerts on the mesh (issue 31), in secure mode (mTLS, access
    control, signed commands): a router, one source at 40x to H+25 min, BN's live EA peer
    armed; BN's commander acknowledges the first urgent BN alert TAK shows: the gateway
    signs it as `tak`, BN's EA takes it (command log, answer in GeoChat) and does not
    re-notify it after, while it re-notifies others."""
    from saim_mesh import scenario as S
    from saim_mesh.launch.proc import Proc, clean_env, py
    from saim_mesh.launch.zenoh_config import free_port
    from saim_mesh.security import endpoint_tls, make_pki, names_for

    from .conftest import SMALL
    from .test_tak_gateway import GROUP, Receivers
    sc = str(SMALL)
    pki = tmp_path / "pki"
    make_pki(pki, [*names_for(S.load(sc, events=False)), "router.hub"])
    sec = ["--pki", str(pki)]
    ep, root = endpoint_tls(free_port()), f"test/{uuid.uuid4().hex[:8]}"
    client = ["--connect", ep, "--mode", "client", "--root", root, *sec, "--routers", "hub"]
    tport, lport = free_port(), free_port()
    uids = tmp_path / "uids.toml"
    uids.write_text(f'[units]\n"{BN_USER}" = "BN"\n')
    rx = Receivers(tport, GROUP, free_port())
    procs: list[Proc] = []
    user = None
    try:
        procs.append(Proc("router", [*py(), "router", "--scenario", sc, "--name", "hub", "--listen", ep, "--root", root,
                                     *sec],
                          env=clean_env(), log_dir=tmp_path))
        procs[-1].wait_for("router ready", 60)
        gw = Proc("tak", [*py(), "tak", sc, *client, "--epoch", "2026-05-01T06:00:00Z",
                          "--cot-url", f"tcp://127.0.0.1:{tport}", "--listen-cot", f"tcp://127.0.0.1:{lport}",
                          "--uids", str(uids), "--no-overlay", "--period", "300", "--linger", "600"],
                  env=clean_env(), log_dir=tmp_path)
        procs.append(gw)
        gw.wait_for("tak ready", 60)
        peer = Proc("BN", [*py(), "peer", "--scenario", sc, "--unit", "BN", *client, "--sources", "cp.BN", "--armed",
                           "--out", str(tmp_path / "BN.jsonl")], env=clean_env(), log_dir=tmp_path)
        procs.append(peer)
        peer.wait_for("ready BN", 60)
        procs.append(Proc("source", [*py(), "source", sc, "--name", "cp.BN", "--tracks", *client, "--speed",
                                     str(SPEED), "--until", str(UNTIL), "--linger", "60"],
                          env=clean_env(), log_dir=tmp_path))

        def first_urgent(got):
            for _, d in got:
                s = C.parse(d).detail.get("__saim", {})
                if s.get("kind") == "alert" and s["owner"] == "BN" and s["priority"] in ("flash", "immediate"):
                    return s["id"]
            return None
        assert rx.wait(first_urgent, 120), "no urgent BN alert on TAK"
        aid = first_urgent(rx.got)
        user = socket.create_connection(("127.0.0.1", lport), timeout=10)
        user.sendall(geochat(BN_USER, "BRAVO6", f"ack {aid}"))

        def said(got):
            return [ev.remarks for _, d in got for ev in [C.parse(d)] if ev.type == A.CHAT
                    and ev.remarks.startswith(f"ACK {aid}")]
        assert rx.wait(said, 30), f"no GeoChat answer to ack {aid}"
        assert said(rx.got)[0].startswith(f"ACK {aid}: taken by the EA of BN at H+"), said(rx.got)
        peer.wait_for("summary ", 200)   # the source's stream ended at UNTIL: the EA finishes
        taken = [c for c in _cmdlog(tmp_path / "BN.cmdlog") if c["kind"] == "ack"]
        assert [(c["cmd"]["alert"], c["ok"], c["cmd"]["by"]) for c in taken] == [(aid, True, f"tak:{BN_USER}")]
        told = [n for n in _notices(tmp_path / "BN.notify.jsonl") if n["kind"] == "renotify"]
        assert told, "armed, BN's EA re-notified nothing"
        assert [n for n in told if n["alert"] == aid and n["t"] > taken[0]["t"]] == []
        gw.stop(30)
        done = gw.wait_for("tak done", 30)
    finally:
        if user is not None:
            user.close()
        for p in procs:
            p.stop(30)
        rx.close()
    assert all(p.p.poll() is not None for p in procs)
    assert "acks=1 (ok 1) ack_refused=0" in done, done
