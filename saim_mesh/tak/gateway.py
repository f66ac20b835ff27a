"""`saim-mesh tak`: the Cursor-on-Target gateway as a Zenoh peer (identity `tak`).

Out: reads the live mesh (`live.reader.LiveReader`: the sources' frames, alerts,
notices, command results, every payload through `gate.Gate` and checked against its
key), keeps the picture (`picture.Picture`, through `TakView`) and sends CoT through
`transports.Network`. In: CoT PLI heard on the listen URLs becomes a LocationReport
(`pli.PliIn`) put into the gateway's own live source `tak` (with --live). Acknowledgements from ATAK users (GeoChat `ack BN/12`, a
`y-a-w` reply to an alert's CoT) go to the alert owner's EA as `ack` commands for the
user's mapped unit (`acks.AckIn`, `ack_send.AckSender`); the EA's answer goes back to the
user in GeoChat.

No liveliness token: the gateway is no EA, nothing waits for it."""
from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from datetime import datetime
from typing import Callable

from ea_agent import domains

from ..protocol import messages as M
from ..protocol import wire as W
from ..live.reader import LiveReader
from .ack_send import AckSender, chat_event
from .acks import AckIn
from .picture import Options, Picture
from .pli import PliIn, load_uids
from .options import DEFAULT_COT_URL, epoch_of
from .transports import Network, TlsOptions

IDENTITY = "tak"
CLASSES = {"suo": (M.LocationReport, M.SensorTrack, M.Reorganization),
           "uv": (M.UvState, M.UvSighting)}


class TakView:
    """What a reader checked, into the picture (a `live.reader.View`); the events it
    yields go to the network. One lock over the picture: the CoT listener's thread reads
    it too (acknowledgements)."""

    def __init__(self, sc, picture: Picture, send: Callable[[bytes], None], overlay_every: float | None = 300.0):
        self.sc, self.picture, self.send = sc, picture, send
        self.overlay_every = overlay_every
        self._overlay_next = 0.0
        self.alerts = 0
        self.quiet = 0   # silenced or inhibited alerts, not sent
        self.lock = threading.Lock()

    def _emit(self, events: list[bytes]) -> None:
        for b in events:
            self.send(b)

    def data(self, msgs: list) -> None:
        with self.lock:
            for m in msgs:
                self.picture.message(m)

    def clock(self, t: float, end: bool, w: float | None = None) -> None:
        """Time moved: the overlay when due, then the positions and tracks due (all at the end)."""
        pic = self.picture
        with self.lock:
            pic.clock(t, end)
            if self.overlay_every is not None and pic.t >= self._overlay_next:
                self._overlay_next = pic.t + self.overlay_every
                self._emit(pic.overlay_events())
            self._emit(pic.due(force=end))

    def alert(self, m: M.Alert) -> None:
        with self.lock:
            self.alerts += 1
            if "silenced" in m.details or "inhibited_by" in m.details:
                self.quiet += 1   # logged by its EA, not pushed to TAK users as new
                return
            self.picture.remember(m)
            self._emit([self.picture.alert_event(m)])

    def result(self, res: W.CmdResult, owner: str) -> str | None:
        """An EA took an acknowledgement: its emergencies end on TAK too."""
        if not (res.ok and res.kind == "ack"):
            return None
        if not res.ref.startswith(f"{owner}/"):   # an EA acknowledges only its own alerts
            return f"alert {res.ref[:60]!r} is not {owner}'s"
        with self.lock:
            self._emit(self.picture.acknowledged(res.ref, owner, res.t))
        return None

    def notice(self, n: W.Notice) -> None:
        """A re-notification: the same CoT uid again (escalations are for consoles)."""
        if n.kind == "renotify" and n.alert.startswith(f"{n.owner}/"):
            with self.lock:
                self._emit(self.picture.renotified(n.alert))


class LiveTakFeed:
    """The gateway on the mesh: a `LiveReader` into the picture, its clock
    the event time every source it heard has promised. PLI in (only with `live_start`,
    event time = wall clock from it) go out as the gateway's own live source `tak`, with a
    watermark every epoch of wall time so that it holds no EA back; an EA takes them when
    `tak` is among its --sources."""
    NAME = "tak-live"
    EPOCH_S = 2.0

    def __init__(self, sc, conf, root: str, picture: Picture, send: Callable[[bytes], None],
                 overlay_every: float | None = 300.0, log: Callable = print, live_start: float | None = None):
        self.view = TakView(sc, picture, send, overlay_every)
        self.reader = LiveReader(sc, conf, root, CLASSES.get(domains.of(sc).NAME, ()), self.view, self.NAME, log)
        self.ks, self.gate, self.log = self.reader.ks, self.reader.gate, log
        self.live_start = live_start
        self.src = None
        self.src_lock = threading.Lock()
        self.pli_refused = 0
        self._stop = threading.Event()

    @property
    def session(self):
        return self.reader.session

    def take(self, key: str, payload: bytes) -> None:
        self.reader.take(key, payload)

    def open(self) -> None:
        self.reader.open()
        if self.live_start is None:
            return
        from ..live.source import LiveSource
        with self.src_lock:
            self.src = LiveSource(self.reader.session, self.ks, IDENTITY, None)
        threading.Thread(target=self._promise, name="tak-watermarks", daemon=True).start()

    def _promise(self) -> None:
        """A watermark at every epoch boundary the wall clock passes: PLI come when they come."""
        while not self._stop.wait(max(0.0, self.EPOCH_S - (time.time() - self.live_start) % self.EPOCH_S)):
            now = time.time() - self.live_start
            with self.src_lock:
                if self.src is not None:
                    self.src.watermark(now - now % self.EPOCH_S)

    def close(self) -> None:
        self._stop.set()
        with self.src_lock:
            if self.src is not None:
                self.src.close(end=True)
                self.src.stop()
                self.src = None
        self.reader.close()

    def publish(self, rep) -> None:
        """A checked LocationReport from a TAK client: into the `tak` source at the wall
        clock's event time (refused, counted, without --live: no event time to give it)."""
        if self.live_start is None:
            self.pli_refused += 1
            if self.pli_refused == 1:
                self.log("tak: PLI into the live mesh need --live (event time = the wall clock): refused", flush=True)
            return
        from dataclasses import replace
        with self.src_lock:
            if self.src is None:
                return
            t = max(round(time.time() - self.live_start, 3), self.src.wm + 0.001)
            try:
                self.src.put(replace(rep, t=t))
            except (ValueError, M.MessageError) as e:
                self.gate.rejects.add(M.MessageError("pli", "(source)", str(e)[:160]), self.ks.src(IDENTITY))


def picture_options(sc, opts) -> Options:
    return Options(period_s=opts.period, refresh_s=opts.refresh, entities=opts.entities, pos_stale_s=opts.stale,
                   alert_stale_s=opts.alert_stale, uid_prefix=opts.uid_prefix,
                   epoch=opts.epoch if isinstance(opts.epoch, datetime) else epoch_of(opts.epoch))


def main_tak(sc, conf, root: str, opts: argparse.Namespace, log: Callable | None = None) -> int:
    """Run the gateway for the mesh at `conf` (zenoh_config.config(..., name="tak") under --pki)
    until every source it hears has ended plus `--linger` wall seconds, SIGTERM or Ctrl-C.
    Prints `tak ready ...` once it listens and subscribes, `tak done ...` at the end."""
    log = log or (lambda *a, **k: print(*a, **k, file=sys.stdout))
    urls = opts.cot_url or [DEFAULT_COT_URL]
    try:
        uids = load_uids(opts.uids, opts.uid_rule) if (opts.uids or opts.uid_rule) else None
        picture = Picture(sc, picture_options(sc, opts))
        pli = PliIn(sc, uids or load_uids(None, None), own=picture.prefix + ".")
    except ValueError as e:
        print(f"saim-mesh tak: {e}", file=sys.stderr, flush=True)
        return 2
    if opts.listen_cot and uids is None:
        log("tak: WARNING: --listen-cot without --uids or --uid-rule: every PLI is an unknown uid", flush=True)
    try:
        from ..security.sign import signer_for
        signer = signer_for(conf)   # secure mode: acknowledgements signed as `tak`
    except Exception as e:
        print(f"saim-mesh tak: {e}", file=sys.stderr, flush=True)
        return 2
    feed_box: list = []   # the LiveTakFeed, once made
    gw_uid, gw_callsign = picture.uid("gateway", "cot"), f"SAIM {sc.name}"
    ack_timeout = float(getattr(opts, "ack_timeout", 10.0))

    def reply(conv, text: str) -> None:
        net.send(chat_event(gw_uid, gw_callsign, conv, text, *picture.centre))

    def send_ack(ack):
        from ..authority import commands
        cmd = commands.make("ack", alert=ack.alert, by=f"tak:{ack.uid}")
        feed = feed_box[0] if feed_box else None
        if feed is None or feed.session is None:
            return commands.result(cmd, False, 0.0, "no answer from the EA: the gateway is not on the mesh")
        return commands.send(feed.session, feed.ks, ack.owner, cmd, ack.by, ack_timeout, signer)

    ack_in = ack_out = None
    if not getattr(opts, "no_acks", False):
        ack_in = AckIn(uids or load_uids(None, None), picture.prefix, lambda: picture.taskorg,
                       lambda u: picture.alert_uids.get(u), log=log)
        ack_out = AckSender(send_ack, reply, log=log)

    def on_data(data: bytes, src: str) -> None:
        ev = pli.parse(data)
        if ev is None:
            return
        if ack_in is not None and ack_in.wants(ev):
            if not feed_box:
                return
            with feed_box[0].view.lock:   # the task organization and the alerts sent, as the feed has them now
                acks, replies = ack_in.take(ev)
            for r in replies:
                reply(r.to, r.text)
            for a in acks:
                ack_out.submit(a)
            return
        rep = pli.take_event(ev, picture.t)
        if rep is not None and feed_box:
            feed_box[0].publish(rep)

    tls = TlsOptions(opts.tls_cert, opts.tls_key, opts.tls_ca, opts.tls_password, opts.tls_no_verify,
                     opts.tls_no_verify, opts.tls_server_name)
    net = Network(urls, opts.proto, opts.listen_cot, opts.mcast_if, opts.mcast_ttl, tls, on_data, log=log,
                  hello=picture.presence_event())
    every = None if opts.no_overlay else opts.overlay_every
    feed = LiveTakFeed(sc, conf, root, picture, net.send, every, log=log, live_start=getattr(opts, "live_start", None))
    feed_box.append(feed)
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        net.start()
    except Exception as e:
        print(f"saim-mesh tak: cannot listen: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
        net.close(0)
        return 2
    try:
        feed.open()
        log(f"tak ready cot={','.join(urls)} proto={opts.proto} "
            f"listen={','.join(net.listening.values()) or '-'} src={feed.ks.src(IDENTITY)}", flush=True)
        ended_at = None
        while not stop.wait(0.2):
            if picture.ended and ended_at is None:
                ended_at = time.monotonic()
                log(f"end of scenario t={picture.t:.0f}: {opts.linger:.0f} s more", flush=True)
            if ended_at is not None and time.monotonic() - ended_at >= opts.linger:
                break
    except KeyboardInterrupt:
        pass
    finally:
        if ack_out is not None:   # acknowledgements under way get their answer before the mesh goes
            ack_out.drain(ack_timeout + 2.0)
        feed.close()
        if ack_out is not None:
            ack_out.close()
        net.close(flush_s=10.0)
    sent = sum(s.n.sent for s in net.senders)
    dropped = sum(s.n.dropped + s.n.failed for s in net.senders)
    made = sum(picture.counts.values())
    by_kind = " ".join(f"{k}={v}" for k, v in sorted(picture.counts.items()))
    cot_rejects = pli.rejected + net.oversized
    acks = ""
    if ack_in is not None:
        def counts(d: dict) -> str:
            return f" ({', '.join(f'{k} {v}' for k, v in sorted(d.items()))})" if d else ""
        refused = dict(ack_in.refused, **({"busy": ack_out.busy} if ack_out.busy else {}))
        acks = (f" acks={ack_in.asked}{counts(ack_out.outcomes)}"
                f" ack_refused={sum(refused.values())}{counts(refused)}")
    log(f"tak done t={picture.t:.0f} events={made} ({by_kind}) sent={sent} dropped={dropped} "
        f"alerts={feed.view.alerts} pli={pli.accepted} rejects={feed.gate.rejects.total} cot_rejects={cot_rejects}"
        + (f" ({', '.join(f'{k} {v}' for k, v in sorted(pli.rejects.items()))})" if pli.rejects else "") + acks,
        flush=True)
    return 0
