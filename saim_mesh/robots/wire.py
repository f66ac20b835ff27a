"""Keys, signatures and frames of the robots' closed loop.

A robot `R` publishes its reports as a live source on `<root>/src/R` (`live.source`:
frames with watermarks). Its EA publishes `tasks.TaskFrame`s on `<root>/task/R`, each
signed with the EA's identity `ea.R` (an Ed25519 envelope, `security.sign`): only `ea.R`
may order R (`RULES`), so a teammate's EA, a console or anyone else signing for that key
is refused by the robot itself, whatever the transport let through."""
from __future__ import annotations

from pathlib import Path

from ea_agent.domains.uv import tasks as T

from ..security.sign import Signer, Verifier, load_keys, load_signer, make_keys

MAX_BYTES = 1 << 16


def task_key(root: str, robot: str) -> str:
    return f"{root}/task/{robot}"


def src_key(root: str, robot: str) -> str:
    return f"{root}/src/{robot}"


def rules(robots: list[str]) -> dict[str, list[str]]:
    """Who may sign which task stream (relative to the root): `ea.R` R's, nobody else."""
    return {f"ea.{r}": [f"task/{r}"] for r in robots}


def make_identities(keys_dir: Path, units: list[str], extra: list[str] = ()) -> None:
    """Signing keys for every unit's EA (and `extra` identities) and signers.json."""
    Path(keys_dir).mkdir(parents=True, exist_ok=True)
    make_keys(keys_dir, [f"ea.{u}" for u in units] + list(extra))


def signer(keys_dir: str | Path, identity: str) -> Signer:
    return load_signer(keys_dir, identity)


def verifier(keys_dir: str | Path, root: str, robots: list[str]) -> Verifier:
    return Verifier(load_keys(keys_dir), rules(robots), root, require=True)


def seal(sig: Signer, key: str, frame: T.TaskFrame) -> bytes:
    return sig.sign(key, T.encode(frame))


def open_frame(ver: Verifier, key: str, payload: bytes, robot: str) -> T.TaskFrame:
    """The checked frame in a signed payload; raises ValueError (MessageError or
    TaskError) naming why it is refused."""
    if len(payload) > MAX_BYTES:
        raise T.TaskError(f"{len(payload)} bytes, over the {MAX_BYTES} limit")
    signed_key, body = ver.open(payload, key)
    if signed_key != key:
        raise T.TaskError(f"signed for {signed_key[:80]!r}, came on {key[:80]!r}")
    f = T.decode(body, MAX_BYTES)
    if f.robot != robot:
        raise T.TaskError(f"a task frame for {f.robot} on {robot}'s key")
    return f
