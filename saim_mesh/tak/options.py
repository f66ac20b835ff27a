"""The TAK gateway's options (`saim-mesh tak`, `python -m saim_mesh.tak`): each value
checked as it is parsed, one line naming what was wrong."""
from __future__ import annotations

import argparse
from datetime import datetime, timezone

from .transports import check_url

DEFAULT_COT_URL = "udp://239.2.3.1:6969"      # TAK clients' situational-awareness multicast group


def epoch_of(v: str) -> datetime:
    if v == "now":
        return datetime.now(timezone.utc)
    try:
        t = datetime.fromisoformat(v[:-1] + "+00:00" if v.endswith("Z") else v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{v!r}: 'now' or an ISO 8601 time like 2026-05-01T06:00:00Z") from None
    return t if t.tzinfo else t.replace(tzinfo=timezone.utc)


def _positive(v: str) -> float:
    try:
        x = float(v)
    except ValueError:
        x = -1.0
    if not x > 0 or x != x or x == float("inf"):
        raise argparse.ArgumentTypeError(f"{v!r}: expected a positive number of seconds")
    return x


def _url(listen: bool):
    def check(v: str) -> str:
        try:
            return check_url(v, listen)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    return check


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The gateway's own options (docs/tak.md); the CLI adds the scenario and Zenoh's."""
    g = p.add_argument_group("Cursor on Target")
    g.add_argument("--cot-url", action="append", type=_url(False), metavar="URL",
                   help=f"where CoT goes, repeatable: udp://GROUP:PORT (multicast SA), tcp://HOST:PORT "
                        f"(a TAK server's stream port), tls://HOST:PORT (with --tls-cert); default {DEFAULT_COT_URL}")
    g.add_argument("--listen-cot", dest="listen_cot", action="append", type=_url(True), default=[], metavar="URL",
                   help="where TAK clients' position reports (PLI) come in, repeatable: udp://GROUP:PORT "
                        "(multicast), udp://HOST:PORT, tcp://HOST:PORT (a listening port)")
    g.add_argument("--proto", choices=["xml", "1"], default="xml",
                   help="xml (CoT XML) or 1 (TAK protocol version 1, protobuf; mesh framing on UDP, "
                        "stream framing on TCP/TLS)")
    g.add_argument("--mcast-if", default="0.0.0.0", metavar="ADDR",
                   help="local interface address for multicast (127.0.0.1: this machine only)")
    g.add_argument("--mcast-ttl", type=int, default=1, metavar="N", help="multicast TTL (0: this host only)")
    g.add_argument("--uids", metavar="FILE", help="uid -> entity map for PLI in (TOML or JSON, "
                                                   "configs/tak-uids.example.toml)")
    g.add_argument("--uid-rule", metavar="RULE",
                   help="uids not in the map: 'uid' (the uid is an entity id), 'callsign' (the callsign is), "
                        "or 'regex:PATTERN' (its 'entity' group, or first group, of the uid)")
    g.add_argument("--period", type=_positive, default=10.0, metavar="S",
                   help="scenario seconds between position updates (only what moved is sent)")
    g.add_argument("--refresh", type=_positive, default=60.0, metavar="S",
                   help="scenario seconds after which an unmoved unit or track is sent again")
    g.add_argument("--entities", action="store_true", help="also send every entity's own position")
    g.add_argument("--no-overlay", action="store_true", help="do not send the scenario's control measures")
    g.add_argument("--overlay-every", type=_positive, default=300.0, metavar="S",
                   help="scenario seconds between re-sending the overlay (late joiners get it)")
    g.add_argument("--epoch", type=epoch_of, default="now", metavar="TIME",
                   help="the UTC time of scenario time 0: 'now' (the gateway's start) or ISO 8601")
    g.add_argument("--stale", type=_positive, default=300.0, metavar="S",
                   help="seconds a position stays valid on a TAK client after its time")
    g.add_argument("--alert-stale", type=_positive, default=1800.0, metavar="S",
                   help="seconds an alert stays on a TAK client after its time")
    g.add_argument("--uid-prefix", metavar="P", help="prefix of every uid we send (default saim.<scenario>)")
    g.add_argument("--live", action="store_true",
                   help="event time is the wall clock from --start; PLI go out as the live source `tak` (EAs "
                        "take them with `--sources ... tak`)")
    g.add_argument("--start", metavar="ISO8601", help="--live: the instant of event time 0 (default now)")
    g.add_argument("--no-acks", action="store_true",
                   help="take no acknowledgements from TAK users (GeoChat 'ack BN/12', a y-a-w reply to an "
                        "alert's CoT): by default they go to the alert's EA as the user's mapped unit")
    g.add_argument("--ack-timeout", type=_positive, default=10.0, metavar="S",
                   help="wall seconds to wait for an EA's answer to an acknowledgement from TAK")
    g.add_argument("--linger", type=float, default=10.0, metavar="S",
                   help="wall seconds to stay up after the scenario's end (PLI in, last events out)")
    t = p.add_argument_group("TLS to a TAK server (tls:// URLs)")
    t.add_argument("--tls-cert", metavar="PEM|P12", help="client certificate (PEM, or PKCS#12 .p12)")
    t.add_argument("--tls-key", metavar="PEM", help="client key (PEM)")
    t.add_argument("--tls-ca", metavar="PEM", help="CA to verify the TAK server with")
    t.add_argument("--tls-password", metavar="PW", help="password of the key or .p12")
    t.add_argument("--tls-no-verify", action="store_true", help="do not verify the server (tests only)")
    t.add_argument("--tls-server-name", metavar="NAME", help="server name expected in its certificate")
