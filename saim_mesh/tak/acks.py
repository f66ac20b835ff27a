"""ATAK closes the loop (issue 33.6): an ATAK user acknowledges an alert from ATAK, and
the alert's EA takes the acknowledgement as from the console of the unit that user acts for.

What ATAK sends, and what is taken as an acknowledgement (docs/tak.md, "Acknowledging
from ATAK"):
- a **GeoChat message** (CoT type `b-t-f`, as ATAK's GeoChatService builds it: uid
  `GeoChat.<sender uid>.<conversation id>.<message id>`, `<__chat id chatroom
  senderCallsign messageId><chatgrp uid0=<sender> uid1=<room or recipient>/></__chat>`,
  `<link uid=<sender> relation="p-p"/>`, `<remarks source="BAO.F.ATAK.<sender>">text`)
  whose text starts with `ack`, `acknowledge(d)` or `wilco` and names alerts: their ids
  (`ack BN/12`, several at once: `ack A/3, A/4`), or the uids of their CoT
  (`<prefix>.alert.BN-12`, as the marker's details show it), or `BN-12`; in any room
  ("All Chat Rooms", a team room) or a direct message to the gateway. A direct message to
  an alert's own uid ("ack" alone) acknowledges that alert.
- a **CoT reply** `y-a-w` ("wilco": MITRE's CoT type tree, `y` = reply to a tasking,
  `a-w` = acknowledged, will comply; `y-a-w-d` too) whose uid is the alert's CoT uid, as
  replies share their request's uid (ATAK's TaskCotReceiver matches them so), from the
  sender its `p-p` link (or `<request _notifyUid>`) names. A `y-a-r` is a machine receipt,
  not a person's acknowledgement: skipped.

Who: the sender's uid -> the unit it acts for (`UidMap.unit`: the uid map's `[units]`
table, else the unit of the entity its `[uids]` table names; never by rule); an unmapped
uid, an alert whose owner that unit does not command (`commands.authority`, on the task
organization as the gateway knows it now), an unknown owner, more than MAX_IDS ids or a
full queue is refused, counted by reason, said in one line and answered in GeoChat. What
is not an acknowledgement (ordinary chat, receipts, our own replies heard back, a message
heard twice, one older than MAX_AGE_S) is skipped, counted apart, not answered.

Each acknowledgement goes to the owner's EA as an `ack` command (by = `tak:<uid>`) for
the mapped unit (key cmd/<owner>/ack/<unit>, signed in secure mode), and the EA's answer
(taken, refused by the EA, or none in time) goes back to the user as a GeoChat reply in
the conversation the acknowledgement came from."""
from __future__ import annotations

import re
from collections import OrderedDict
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Callable

from . import cot as C

CHAT = "b-t-f"                      # a GeoChat message (its receipts are b-t-f-d, -r, -p, -s)
WILCO = "y-a-w"                     # a CoT reply: acknowledged, will comply (y-a-w-d: degraded)
MACHINE_ACK = "y-a-r"               # a CoT reply: received by the machine (not a person)
ALL_CHAT = "All Chat Rooms"         # ATAK's default room (GeoChatService.DEFAULT_CHATROOM_NAME)
ROOT_GROUP = "RootContactGroup"
WORDS = frozenset({"ack", "acknowledge", "acknowledged", "wilco"})
SOURCES = ("BAO.F.ATAK.", "BAO.F.WinTAK.")   # remarks source = <client>.<sender uid>
MAX_TEXT = 1000          # characters of a chat message looked at
MAX_IDS = 8              # alerts one message may acknowledge
MAX_UID = 100            # a TAK uid longer than this is not one we map (by = tak:<uid> fits 128)
MAX_PENDING = 32         # acknowledgements waiting for an EA's answer; more are refused (busy)
MAX_SEEN = 4096          # messages remembered to drop the same one heard twice (multicast and server)
MAX_AGE_S = 600.0        # an acknowledgement dated longer ago than this is history (a server's replay)
LOG_FIRST = 200          # refusal lines said; then one in every LOG_EVERY
LOG_EVERY = 100
_SPLIT = re.compile(r"[\s,;]+")
_N = re.compile(r"^w?[0-9]{1,9}(\.[0-9a-f]{4}(\.[0-9]{1,3})?)?$")   # ea_agent/core/ids.py
_UID = re.compile(r"^[^\x00-\x20\x7f]{1,%d}$" % MAX_UID)


class AckError(ValueError):
    """An acknowledgement we refuse: `reason` is what it is counted under."""

    def __init__(self, reason: str, why: str):
        self.reason = reason
        super().__init__(why)


@dataclass(frozen=True, slots=True)
class Conversation:
    """Where a reply goes: GeoChat's conversation `id` and `room` (its display name),
    `dest` (chatgrp uid1: the room, or the recipient of a direct message) and, for a
    direct message, the recipient's callsign (a TAK server routes on `<marti><dest>`)."""
    id: str
    room: str
    dest: str
    to_callsign: str | None = None


@dataclass(frozen=True, slots=True)
class Ack:
    """One acknowledgement to send: `alert` of `owner`'s EA, as the console of unit `by`,
    from the ATAK user `uid` (`callsign`), answered in `reply`."""
    alert: str
    owner: str
    by: str
    uid: str
    callsign: str
    form: str            # "chat" or "wilco"
    reply: Conversation


@dataclass(frozen=True, slots=True)
class Reply:
    """A GeoChat answer to send back."""
    to: Conversation
    text: str


def _uid(v, what: str) -> str:
    if not isinstance(v, str) or not _UID.match(v):
        raise AckError("sender", f"{what} {str(v)[:40]!r} is not a usable TAK uid")
    return v


def is_chat(t: str) -> bool:
    return t == CHAT


def is_wilco(t: str) -> bool:
    return t == WILCO or t.startswith(WILCO + "-")


def chat_sender(ev: C.CoTEvent) -> str:
    """The sender of a GeoChat message: chatgrp uid0, the p-p link, the remarks' sourceID
    or source (`BAO.F.ATAK.<uid>`); every one present must agree (ATAK sets them all)."""
    found = []
    g = ev.detail.get("__chat/chatgrp", {}).get("uid0")
    if g:
        found.append(g)
    link = next((lk.get("uid") for lk in ev.links if lk.get("relation") == "p-p" and lk.get("uid")), None)
    if link:
        found.append(link)
    rm = ev.detail.get("remarks", {})
    if rm.get("sourceID"):
        found.append(rm["sourceID"])
    elif rm.get("source"):
        found += [rm["source"][len(p):] for p in SOURCES if rm["source"].startswith(p)]
    if not found:
        raise AckError("sender", f"{ev.uid[:60]}: no sender (chatgrp uid0, link p-p, remarks source)")
    if len(set(found)) > 1:
        raise AckError("sender", f"{ev.uid[:60]}: its sender uids disagree ({', '.join(sorted(set(found)))[:120]})")
    return _uid(found[0], "sender")


def wilco_sender(ev: C.CoTEvent) -> str:
    """The sender of a CoT reply: its p-p link's uid, or `<request _notifyUid>` (agreeing)."""
    found = [lk["uid"] for lk in ev.links if lk.get("relation") == "p-p" and lk.get("uid")][:1]
    n = ev.detail.get("request", {}).get("_notifyUid")
    if n:
        found.append(n)
    if not found:
        raise AckError("sender", f"{ev.uid[:60]}: a {ev.type} with no sender (link relation p-p or request _notifyUid)")
    if len(set(found)) > 1:
        raise AckError("sender", f"{ev.uid[:60]}: its sender uids disagree ({', '.join(sorted(set(found)))[:120]})")
    return _uid(found[0], "sender")


def ack_words(text: str) -> list[str] | None:
    """The words after the acknowledgement word, or None when the text is not one."""
    words = [w for w in _SPLIT.split(text.strip()[:MAX_TEXT]) if w]
    if not words or words[0].lower().rstrip(":.!-") not in WORDS:
        return None
    return words[1:]


class AckIn:
    """CoT from TAK users -> acknowledgements to send (`Ack`) and answers (`Reply`).

    `prefix`: our uid prefix (alerts are `<prefix>.alert.<owner>-<n>`, the gateway
    `<prefix>.gateway.cot`); `taskorg()`: the task organization as the gateway knows it
    now (reorganizations included); `sent(uid)`: the alert id of an alert CoT uid we sent
    (None if not remembered)."""

    def __init__(self, uids, prefix: str, taskorg: Callable[[], object],
                 sent: Callable[[str], str | None] = lambda u: None,
                 clock: Callable[[], datetime] | None = None, log: Callable = print, max_age_s: float = MAX_AGE_S):
        self.uids, self.prefix, self.taskorg, self.sent = uids, prefix, taskorg, sent
        self.gateway = f"{prefix}.gateway.cot"
        self.alert_prefix = f"{prefix}.alert."
        self.clock = clock or (lambda: datetime.now(timezone.utc))
        self.log, self.max_age_s = log, max_age_s
        self.asked = 0                         # acknowledgements handed on (one per alert named)
        self.refused: dict[str, int] = {}      # refused here, by reason
        self.skipped: dict[str, int] = {}      # not acknowledgements, by kind
        self.seen: OrderedDict[str, None] = OrderedDict()
        self._said = 0

    @property
    def refusals(self) -> int:
        return sum(self.refused.values())

    def wants(self, ev: C.CoTEvent) -> bool:
        """Chat and CoT replies are ours to look at (not PLI)."""
        return is_chat(ev.type) or ev.type.startswith("y-")

    def _skip(self, kind: str) -> tuple[list, list]:
        self.skipped[kind] = self.skipped.get(kind, 0) + 1
        return [], []

    def _refuse(self, reason: str, why: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1
        self._said += 1
        if self._said <= LOG_FIRST or self._said % LOG_EVERY == 0:
            self.log(f"tak: ack refused ({reason}): {why}"[:300], flush=True)

    def _once(self, key: str) -> bool:
        """First time heard (a message comes on multicast and from a server alike)."""
        if key in self.seen:
            return False
        self.seen[key] = None
        if len(self.seen) > MAX_SEEN:
            self.seen.popitem(last=False)
        return True

    # -- what the user named -----------------------------------------------------------
    def alert_id(self, token: str) -> str | None:
        """An alert id from what a user typed: `BN/942.8f85`, `BN-942.8f85`, our CoT uid of it; None
        when the word is not one (free text after the ids)."""
        tok = token.strip("()[]<>\"'.")
        if tok.startswith(self.alert_prefix):
            known = self.sent(tok)
            if known is not None:
                return known
            tok = tok[len(self.alert_prefix):]
            sep = "-"
        else:
            sep = "/" if "/" in tok else "-"
        owner, _, n = tok.rpartition(sep)
        if not owner or not _N.match(n) or len(owner) > 64:
            return None
        units = self.taskorg().units
        if owner not in units:   # `ack bn/3`: the unit's id whatever its case, if unambiguous
            same = [u for u in units if u.lower() == owner.lower()]
            if len(same) == 1:
                owner = same[0]
            elif sep == "-" and not token.startswith(self.alert_prefix):
                return None   # `12-30`: a word with a dash, not an alert (`X/1` names one, known or not)
        return f"{owner}/{n}"

    # -- one event ---------------------------------------------------------------------
    def take(self, ev: C.CoTEvent) -> tuple[list[Ack], list[Reply]]:
        """One parsed event (chat or a CoT reply) -> (acknowledgements to send, answers)."""
        now = self.clock()
        if is_chat(ev.type):
            return self._chat(ev, now)
        if is_wilco(ev.type):
            return self._wilco(ev, now)
        return self._skip("machine-ack" if ev.type.startswith(MACHINE_ACK) else "other-reply")

    def _fresh(self, ev: C.CoTEvent, now: datetime) -> bool:
        return ev.stale >= now and (now - ev.time).total_seconds() <= self.max_age_s

    def _chat(self, ev: C.CoTEvent, now: datetime):
        try:
            sender = chat_sender(ev)
        except AckError as e:
            if ack_words(ev.remarks or "") is None:
                return self._skip("chat")
            self._refuse(e.reason, str(e))
            return [], []
        if sender == self.gateway or sender.startswith(self.prefix + "."):
            return self._skip("own")
        words = ack_words(ev.remarks or "")
        if words is None:
            return self._skip("chat")
        chat = ev.detail.get("__chat", {})
        conv_id = chat.get("id") or ALL_CHAT
        dest = ev.detail.get("__chat/chatgrp", {}).get("uid1") or conv_id
        callsign = (chat.get("senderCallsign") or sender)[:64]
        direct = conv_id in (self.gateway,) or dest == self.gateway or conv_id.startswith(self.alert_prefix)
        reply = (Conversation(sender, callsign, sender, callsign) if direct
                 else Conversation(conv_id[:128], (chat.get("chatroom") or conv_id)[:128], dest[:128]))
        named = [a for a in map(self.alert_id, words[: 4 * MAX_IDS]) if a is not None]
        if not named and conv_id.startswith(self.alert_prefix):   # a direct message to the alert itself
            named = [a for a in [self.alert_id(conv_id)] if a is not None]
        if not named:
            return self._skip("chat")   # "ack, moving": talk, not an acknowledgement of an alert
        if not self._fresh(ev, now):
            return self._skip("old")
        if not self._once(ev.uid):
            return self._skip("duplicate")
        return self._named(named, sender, callsign, "chat", reply)

    def _wilco(self, ev: C.CoTEvent, now: datetime):
        if not ev.uid.startswith(self.alert_prefix):
            return self._skip("not-ours")   # a reply to someone else's tasking
        try:
            sender = wilco_sender(ev)
        except AckError as e:
            self._refuse(e.reason, str(e))
            return [], []
        if not self._fresh(ev, now):
            return self._skip("old")
        if not self._once(f"{ev.uid}|{sender}|{C.iso(ev.time)}"):
            return self._skip("duplicate")
        callsign = (ev.callsign or next((lk.get("parent_callsign") for lk in ev.links
                                         if lk.get("uid") == sender and lk.get("parent_callsign")), None)
                    or sender)[:64]
        aid = self.alert_id(ev.uid)
        reply = Conversation(sender, callsign, sender, callsign)
        if aid is None:
            self._refuse("bad-id", f"{callsign} ({sender}): {ev.uid[:80]} names no alert")
            return [], [Reply(reply, f"ACK refused: {ev.uid[:80]} is not an alert of ours")]
        return self._named([aid], sender, callsign, "wilco", reply)

    def _named(self, named: list[str], sender: str, callsign: str, form: str, reply: Conversation):
        who = f"{callsign} ({sender})"
        named = list(dict.fromkeys(named))
        if len(named) > MAX_IDS:
            self._refuse("too-many", f"{who}: {len(named)} alerts in one message (at most {MAX_IDS})")
            return [], [Reply(reply, f"ACK refused: {len(named)} alerts in one message, at most {MAX_IDS}")]
        to = self.taskorg()
        by = self.uids.unit(sender, to.entity_unit)
        if by is None or by not in to.units:
            self._refuse("unknown-uid", f"{who} is not mapped to a unit (acks {', '.join(named)})")
            return [], [Reply(reply, f"ACK {', '.join(named)} refused: {callsign} ({sender}) is not mapped to a "
                                     f"unit at the gateway")]
        from ..authority.commands import authority
        acks, replies = [], []
        for aid in named:
            owner = aid.rsplit("/", 1)[0]
            if owner not in to.units:
                self._refuse("unknown-owner", f"{who} as {by}: {aid}: {owner[:40]!r} is not a unit")
                replies.append(Reply(reply, f"ACK {aid} refused: {owner[:40]} is not a unit of this mesh"))
                continue
            if authority(to, by, owner) is not None:
                chain = "/".join([*reversed(to.ancestors(owner)), owner])
                self._refuse("authority", f"{who} as {by}: {aid}: {by} does not command {owner} (chain {chain})")
                replies.append(Reply(reply, f"ACK {aid} refused: {callsign} acts for {by}, which does not "
                                            f"command {owner} ({chain})"))
                continue
            self.asked += 1
            acks.append(Ack(aid, owner, by, sender, callsign, form, reply))
        return acks, replies
