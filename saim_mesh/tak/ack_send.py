"""What goes back once an ATAK user's acknowledgement is read (`acks.AckIn`): the
acknowledgement to the alert's EA on worker threads (an answer takes a round trip, or a
timeout when the EA is away: the listeners never wait for it), and the EA's answer to the
user as a GeoChat message built as ATAK's own, in the conversation it came from."""
from __future__ import annotations

import queue
import threading
import xml.etree.ElementTree as ET
from datetime import datetime, timedelta, timezone
from typing import Callable
from uuid import uuid4

from ea_agent.core.alert import hms

from . import cot as C
from .acks import CHAT, MAX_PENDING, MAX_TEXT, ROOT_GROUP, Ack, Conversation

def answer(ack: Ack, res) -> tuple[str, str]:
    """(outcome, GeoChat text) of the EA's answer `res` (a CmdResult) to `ack`."""
    if res.ok:
        return "ok", (f"ACK {ack.alert}: taken by the EA of {ack.owner} at {hms(res.t)} "
                      f"({ack.callsign} as {ack.by}): its re-notifications stop")
    if res.error.startswith(("no EA of", "no answer from")):
        return "no-answer", f"ACK {ack.alert} not taken: {res.error}"
    return "refused-by-ea", f"ACK {ack.alert} refused by the EA of {ack.owner}: {res.error}"


def chat_event(gateway: str, callsign: str, to: Conversation, text: str, lon: float, lat: float,
               now: datetime | None = None) -> bytes:
    """A GeoChat message from the gateway, built as ATAK's GeoChatService builds one
    (uid `GeoChat.<sender>.<conversation>.<message id>`, `__chat`/`chatgrp`, the p-p link
    to the sender, remarks with source and time), so ATAK files it in that conversation;
    a direct message carries `<marti><dest callsign>` for a TAK server to route it."""
    now = now or datetime.now(timezone.utc)
    mid = uuid4().hex
    chat = ET.Element("__chat", {"parent": ROOT_GROUP, "groupOwner": "false", "messageId": mid,
                                 "chatroom": to.room, "id": to.id, "senderCallsign": callsign})
    ET.SubElement(chat, "chatgrp", {"uid0": gateway, "uid1": to.dest, "id": to.id})
    det = [chat, ET.Element("link", {"uid": gateway, "type": "a-f-G-E-S", "relation": "p-p"})]
    if to.to_callsign:
        marti = ET.Element("marti")
        ET.SubElement(marti, "dest", {"callsign": to.to_callsign})
        det.append(marti)
    rm = ET.Element("remarks", {"source": f"BAO.F.ATAK.{gateway}", "time": C.iso(now),
                                **({"to": to.dest} if to.to_callsign else {})})
    rm.text = text[:MAX_TEXT]
    det.append(rm)
    return C.event(f"GeoChat.{gateway}.{to.id}.{mid}", CHAT, lon, lat, now, now + timedelta(days=1),
                   how="h-g-i-g-o", detail=det)


class AckSender:
    """Acknowledgements to the EAs on worker threads (an EA's answer takes a round trip,
    or `timeout` when it is away: the listeners never wait for it). `send(ack)` returns the
    EA's CmdResult; `reply(conversation, text)` sends a GeoChat answer."""

    def __init__(self, send: Callable[[Ack], object], reply: Callable[[Conversation, str], None],
                 workers: int = 2, max_pending: int = MAX_PENDING, log: Callable = print):
        self.send, self.reply, self.log = send, reply, log
        self.q: queue.Queue = queue.Queue(maxsize=max_pending)
        self.outcomes: dict[str, int] = {}
        self.busy = 0
        self.lock = threading.Lock()
        self.threads = [threading.Thread(target=self._run, name=f"tak-ack-{i}", daemon=True) for i in range(workers)]
        for t in self.threads:
            t.start()

    def submit(self, ack: Ack) -> bool:
        """Queue one; False (said and answered) when MAX_PENDING are already waiting."""
        try:
            self.q.put_nowait(ack)
            return True
        except queue.Full:
            with self.lock:
                self.busy += 1
            self.log(f"tak: ack refused (busy): {ack.alert} from {ack.callsign} ({ack.uid})", flush=True)
            self.reply(ack.reply, f"ACK {ack.alert} refused: the gateway has {self.q.maxsize} acknowledgements "
                                  f"waiting; send it again")
            return False

    def _run(self) -> None:
        while True:
            ack = self.q.get()
            try:
                if ack is None:
                    return
                try:
                    res = self.send(ack)
                    outcome, text = answer(ack, res)
                except Exception as e:   # a failure here is one ack's, never the gateway's
                    outcome, text = "error", f"ACK {ack.alert} not taken: {type(e).__name__}: {str(e)[:160]}"
                with self.lock:
                    self.outcomes[outcome] = self.outcomes.get(outcome, 0) + 1
                self.log(f"tak: ack {ack.alert} from {ack.callsign} ({ack.uid}) as {ack.by}: {outcome}"
                         + ("" if outcome == "ok" else f" ({text.split(': ', 1)[-1][:160]})"), flush=True)
                self.reply(ack.reply, text)
            finally:
                self.q.task_done()

    def drain(self, timeout: float) -> bool:
        """Wait (bounded) until every queued acknowledgement was answered."""
        done = threading.Event()
        threading.Thread(target=lambda: (self.q.join(), done.set()), daemon=True).start()
        return done.wait(timeout)

    def close(self, timeout: float = 2.0) -> None:
        for _ in self.threads:
            try:
                self.q.put(None, timeout=timeout)
            except queue.Full:
                break
        for t in self.threads:
            t.join(timeout)
