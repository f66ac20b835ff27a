"""Signatures that survive relays: Ed25519 envelopes around the payloads that carry authority.

Through a Zenoh router the receiver's access control sees the router's certificate, not
the publisher's (../shared/notes/zenoh-security.md), so an order, a reorganization, a
mission confirmation, a robot's task delegation or a commander's command is also signed
with the sender's own key and checked by the receiver itself.

A `Signed` envelope, (v, by, n, key, body, sig), travels as msgpack ext type 83 (a data
message is a map, a control message or batch a map or an array: the first byte tells them
apart); `sig` covers a canonical encoding of (by, n, key, body), so a signed message
cannot be moved to another key or claimed by another signer.
`n` is a counter strictly new per signer: time-based (microseconds since the epoch,
strictly increasing), so a restarted signer never reuses one. A `Verifier` rejects, with a `MessageError` of kind "signed" naming why: an
undecodable envelope, an unknown signer, a signer not allowed on that key family, a key
other than the one the envelope came on, a bad signature, and an `n` it has taken before
(or older than its window of the last `window` taken per signer).

Files (made by `pki.make_pki` beside the certificates): NAME.sign.pem (PKCS#8, mode 600)
and signers.json (every identity's public key), see `make_keys`.
"""
from __future__ import annotations

import heapq
import json
import time
from pathlib import Path
from typing import Annotated, Callable, Iterable, Literal

import msgspec
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from dissemination.keyspace import KeySpace
from saim_mesh.protocol import messages as M
from saim_mesh.protocol import wire as W

from .pki import NAME_RE, SecurityError, _load_key, _read, _write

VERSION = 1
KIND = "signed"                  # what a rejected envelope is counted under (gate.Rejects)
EXT = 83                         # msgpack ext type of an envelope ('S')
SIGNERS_FILE = "signers.json"
SIGN_SUFFIX = ".sign.pem"
MAX_BODY = 1 << 20               # the Gate's size bound on the whole envelope comes first
WINDOW = 4096                    # counters remembered per signer
_DOMAIN = "saim-mesh signed v1"  # what a signature is for: never valid for anything else

# what carries authority: these message kinds must come signed in secure mode (nobody signs them on
# a data key today: orders and confirmations travel as directives, saim_mesh/authority/directives.py)
AUTHORITY: tuple[type, ...] = (M.Order, M.Reorganization, M.MissionConfirm, M.UvAgent)
COMMAND_FAMILY = "cmd"
NOTICE_FAMILY = "notice"
DIRECTIVE_FAMILY = "dir"    # orders down, confirmations up (saim_mesh/authority/directives.py)

Name = Annotated[str, msgspec.Meta(min_length=1, max_length=128, pattern=NAME_RE.pattern)]


class Signed(msgspec.Struct, frozen=True, array_like=True, forbid_unknown_fields=True):
    """A payload signed by identity `by` for key expression `key`, its `n`-th."""
    v: Literal[1]
    by: Name
    n: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]
    key: Annotated[str, msgspec.Meta(min_length=1, max_length=W.KEY_LIMIT)]
    body: Annotated[bytes, msgspec.Meta(max_length=MAX_BODY)]
    sig: Annotated[bytes, msgspec.Meta(min_length=64, max_length=64)]


class SignersFile(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """signers.json: every identity's raw Ed25519 public key (base64 in JSON)."""
    v: Literal[1]
    keys: Annotated[dict[Name, Annotated[bytes, msgspec.Meta(min_length=32, max_length=32)]],
                    msgspec.Meta(max_length=100_000)]


_ENC = msgspec.msgpack.Encoder()
_DEC = msgspec.msgpack.Decoder(Signed)
_EXT_DEC = msgspec.msgpack.Decoder(msgspec.msgpack.Ext)


def _err(field: str, problem: str) -> M.MessageError:
    return M.MessageError(KIND, field, problem)


def is_signed(payload: bytes) -> bool:
    """An envelope (a msgpack ext), not a bare message: one byte decides."""
    return payload[:1] in W.ENVELOPE_HEADS


def envelope(payload: bytes) -> Signed:
    """The envelope in `payload`, not yet checked; MessageError when there is none."""
    try:
        ext = _EXT_DEC.decode(payload)
        if ext.code != EXT:
            raise _err("(envelope)", f"msgpack ext type {ext.code}, not a signed envelope ({EXT})")
        return _DEC.decode(ext.data)
    except (msgspec.ValidationError, msgspec.DecodeError) as e:
        raise _err("(envelope)", str(e)[:200]) from None


def _canonical(by: str, n: int, key: str, body: bytes) -> bytes:
    return _ENC.encode((_DOMAIN, by, n, key, body))


class Signer:
    """Signs payloads as identity `name`. `n` is given (a directive carries the one it
    was signed with: `next_n`) or time-based: microseconds since the epoch, strictly
    increasing, so a restarted console never reuses one."""

    def __init__(self, name: str, private_key: Ed25519PrivateKey):
        if not NAME_RE.match(name) or len(name) > 128:
            raise SecurityError(f"bad signer name {name!r}")
        if not isinstance(private_key, Ed25519PrivateKey):
            raise SecurityError(f"signer {name}: not an Ed25519 private key ({type(private_key).__name__})")
        self.name, self._key = name, private_key
        self._last = 0

    def next_n(self) -> int:
        self._last = max(self._last + 1, time.time_ns() // 1000)
        return self._last

    def sign(self, key: str, body: bytes, n: int | None = None) -> bytes:
        """The encoded envelope of `body` for key expression `key`."""
        n = self.next_n() if n is None else int(n)
        if not 1 <= n <= W.SEQ_LIMIT:
            raise ValueError(f"counter {n} outside [1, {W.SEQ_LIMIT}]")
        if len(body) > MAX_BODY or not 1 <= len(key) <= W.KEY_LIMIT:
            raise ValueError(f"cannot sign {len(body)} bytes for a key of {len(key)} characters")
        sig = self._key.sign(_canonical(self.name, n, key, body))
        return _ENC.encode(msgspec.msgpack.Ext(EXT, _ENC.encode(Signed(v=VERSION, by=self.name, n=n, key=key,
                                                                      body=body, sig=sig))))


def seal(signer: Signer | None, key: str, msg, payload: bytes, n: int) -> bytes:
    """`payload` signed when `msg` carries authority and there is a signer (secure mode);
    as it is otherwise."""
    return payload if signer is None or type(msg) not in AUTHORITY else signer.sign(key, payload, n)


def rules_for(identities: Iterable[str]) -> dict[str, list[str]]:
    """Which identity may sign which keys (relative to the root), as the access control
    lets them publish today: `console` any command;
    `console.U` commands sent as U's console (`cmd/<unit>/<kind>/U`). Nobody else."""
    out: dict[str, list[str]] = {}
    for name in identities:
        if name == "console":
            out[name] = [f"{COMMAND_FAMILY}/**"]
        elif name == "tak":   # an ATAK user's acknowledgement, as the console of the unit its uid maps to
            out[name] = [f"{COMMAND_FAMILY}/*/ack/*"]
        elif name.startswith("console.") and len(name) > 8:   # ... and U's directives (orders, confirmations)
            out[name] = [f"{COMMAND_FAMILY}/*/*/{name[8:]}", f"{DIRECTIVE_FAMILY}/{name[8:]}/*"]
        elif name.startswith("ea.") and len(name) > 3:   # its escalations cross routers to its superior
            out[name] = [f"{NOTICE_FAMILY}/*/{name[3:]}", f"{DIRECTIVE_FAMILY}/{name[3:]}/confirm"]
    return out


def _rule(expr: str) -> Callable[[str], bool]:
    """A test of concrete keys against one rule: `*` is one chunk, a trailing `**` any rest.
    Our own, not Zenoh's: a signed key is attacker input, and it must not raise."""
    parts = expr.split("/")
    deep = parts[-1] == "**"
    if deep:
        parts = parts[:-1]

    def match(key: str) -> bool:
        chunks = key.split("/")
        if len(chunks) < len(parts) or not deep and len(chunks) != len(parts):
            return False
        return all(p == "*" or p == c for p, c in zip(parts, chunks))
    return match


def _any(exprs: list[str]) -> Callable[[str], bool]:
    tests = [_rule(e) for e in exprs]
    return lambda key: any(t(key) for t in tests)


class _Window:
    """The last `size` counters taken from one signer: a counter seen again, or older than
    all of them once the window is full, is a replay. Memory: `size` integers."""
    __slots__ = ("size", "seen", "heap", "floor")

    def __init__(self, size: int):
        self.size, self.seen, self.heap, self.floor = size, set(), [], 0

    def why_not(self, n: int) -> str | None:
        if n in self.seen:
            return f"replayed: counter {n} already taken"
        if n <= self.floor:
            return f"replayed: counter {n} older than the last {self.size} taken (from {self.floor + 1})"
        return None

    def take(self, n: int) -> None:
        if n in self.seen or n <= self.floor:
            return
        self.seen.add(n)
        heapq.heappush(self.heap, n)
        if len(self.heap) > self.size:
            self.floor = heapq.heappop(self.heap)
            self.seen.discard(self.floor)


class Verifier:
    """Checks envelopes against the signers' public keys and `rules` (identity -> key
    expressions relative to `root` it may sign, `rules_for`). `require`: secure mode, an
    authority message or a command must come signed."""

    def __init__(self, keys: dict[str, Ed25519PublicKey], rules: dict[str, list[str]], root: str,
                 require: bool = True, window: int = WINDOW):
        self.ks = KeySpace(root)
        self.keys = dict(keys)
        self.allowed: dict[str, Callable[[str], bool]] = {
            who: _any([f"{self.ks.root}/{e}" for e in exprs]) for who, exprs in rules.items()}
        self.require, self.window = require, int(window)
        self.windows: dict[str, _Window] = {}
        self._data_prefix, self._store_prefix = self.ks.root + "/", self.ks.root + "/store/"

    def open(self, payload: bytes, key: str | None) -> tuple[str, bytes]:
        """(signed key, body) of a valid envelope; raises MessageError naming why not.

        `key` is the key expression it came on. A store entry has none of its own (None,
        or a label outside the root such as "store"): its signed key stands, its counter
        is remembered but not refused again: the replay answers the store, its readers
        drop repeats by sequence number, and a peer re-fetches there what it dropped."""
        try:
            env = envelope(payload)
        except M.MessageError:
            raise
        except Exception as e:   # a decoder bug must not kill a peer either
            raise _err("(envelope)", f"undecodable: {type(e).__name__}") from None
        if any(c in env.key for c in "*$?#") or "//" in env.key or env.key.endswith("/"):
            raise _err("key", f"signed for {env.key[:80]!r}: not one concrete key")
        pub = self.keys.get(env.by)
        if pub is None:
            raise _err("by", f"unknown signer {env.by[:64]!r}")
        allowed = self.allowed.get(env.by)
        if allowed is None or not allowed(env.key):
            raise _err("by", f"{env.by} may not sign on {self.ks.family(env.key)[:32]!r} keys "
                             f"({env.key[:80]!r})")
        live = key is not None and key.startswith(self._data_prefix) and not key.startswith(self._store_prefix)
        if live and key != env.key:
            raise _err("key", f"signed for {env.key[:80]!r}, came on {key[:80]!r}")
        win = self.windows.get(env.by)
        if live and win is not None and (why := win.why_not(env.n)) is not None:
            raise _err("n", f"{why} from {env.by}")
        try:
            pub.verify(env.sig, _canonical(env.by, env.n, env.key, env.body))
        except InvalidSignature:
            raise _err("sig", f"bad signature (claimed by {env.by})") from None
        if win is None:
            win = self.windows[env.by] = _Window(self.window)
        win.take(env.n)
        return env.key, env.body

    def bind(self, signed_key: str, msg) -> None:
        """The message inside must be what its signed key says (an order on ord/A2 is
        issued by A2; an authority message under its own family)."""
        try:
            why = self.ks.mismatch(signed_key, msg)
        except ValueError as e:   # a kind with no key template: never signed
            why = str(e)
        if why is not None:
            raise _err("key", f"{msg.KIND} inside: {why}")

    @property
    def guarded(self) -> tuple[type, ...]:
        """The message types `unsigned` may refuse (none when signatures are not required)."""
        return AUTHORITY if self.require else ()

    def unsigned(self, msg) -> None:
        """Raise when `msg` carries authority, came unsigned and signatures are required."""
        if self.require and type(msg) in AUTHORITY:
            raise M.MessageError(msg.KIND, "(signature)", f"an unsigned {msg.KIND} message: "
                                 "authority must be signed in secure mode")


# ---------------------------------------------------------------------------- files

def _pub_raw(key: Ed25519PrivateKey) -> bytes:
    return key.public_key().public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)


def _load_private(path: Path) -> Ed25519PrivateKey:
    key = _load_key(path)
    if not isinstance(key, Ed25519PrivateKey):
        raise SecurityError(f"{path}: not an Ed25519 signing key ({type(key).__name__})")
    return key


def make_keys(out_dir: str | Path, names: Iterable[str]) -> dict[str, Path]:
    """Make (or keep) NAME.sign.pem for each name and write signers.json with the public
    key of every NAME.sign.pem in OUT_DIR. Idempotent: a readable key is kept and
    signers.json is rewritten only when its content changes. Returns {name: key path}."""
    d = Path(out_dir).resolve()
    out: dict[str, Path] = {}
    for n in dict.fromkeys(names):
        p = d / f"{n}{SIGN_SUFFIX}"
        try:
            _load_private(p)
        except SecurityError:
            key = Ed25519PrivateKey.generate()
            _write(p, key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                        serialization.NoEncryption()), 0o600)
        out[n] = p
    keys: dict[str, bytes] = {}
    for p in sorted(d.glob(f"*{SIGN_SUFFIX}")):
        n = p.name[:-len(SIGN_SUFFIX)]
        if NAME_RE.match(n):
            try:
                keys[n] = _pub_raw(_load_private(p))
            except SecurityError:
                continue   # a damaged key of an identity not asked for: left out, not trusted
    data = json.dumps(json.loads(msgspec.json.encode(SignersFile(v=VERSION, keys=keys))), indent=1,
                      sort_keys=True).encode() + b"\n"
    f = d / SIGNERS_FILE
    if not f.is_file() or f.read_bytes() != data:
        _write(f, data, 0o644)
    return out


def load_signer(pki_dir: str | Path, name: str) -> Signer:
    return Signer(name, _load_private(Path(pki_dir) / f"{name}{SIGN_SUFFIX}"))


def load_keys(pki_dir: str | Path) -> dict[str, Ed25519PublicKey]:
    path = Path(pki_dir) / SIGNERS_FILE
    try:
        f = msgspec.json.decode(_read(path), type=SignersFile)
    except (msgspec.ValidationError, msgspec.DecodeError) as e:
        raise SecurityError(f"{path}: bad signers file ({str(e)[:200]})") from None
    return {n: Ed25519PublicKey.from_public_bytes(k) for n, k in f.keys.items()}


def load_verifier(pki_dir: str | Path, root: str, require: bool = True, window: int = WINDOW) -> Verifier:
    keys = load_keys(pki_dir)
    return Verifier(keys, rules_for(keys), root, require, window)


def identity_of(conf) -> tuple[Path, str] | None:
    """(pki folder, identity) of a Zenoh config made with `--pki` (its TLS certificate
    NAME.pem), or None: open mode."""
    try:
        cert = json.loads(conf.get_json("transport/link/tls/connect_certificate"))
    except Exception:
        return None
    if not isinstance(cert, str) or not cert.endswith(".pem"):
        return None
    p = Path(cert)
    return p.parent, p.name[:-len(".pem")]


def _missing(d: Path, e: SecurityError) -> SecurityError:
    return SecurityError(f"{e} (signing keys: run `saim-mesh certs` for {d} again)")


def signer_for(conf) -> Signer | None:
    """This process's signer in secure mode (None in open mode); SecurityError when the
    pki folder has certificates but no signing key for the identity."""
    who = identity_of(conf)
    if who is None:
        return None
    try:
        return load_signer(*who)
    except SecurityError as e:
        raise _missing(who[0], e) from None


def verifier_for(conf, root: str, window: int = WINDOW) -> Verifier | None:
    """The verifier of a secure process (signatures required), or None in open mode."""
    who = identity_of(conf)
    if who is None:
        return None
    try:
        return load_verifier(who[0], root, True, window)
    except SecurityError as e:
        raise _missing(who[0], e) from None
