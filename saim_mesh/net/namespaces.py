"""This machine's network namespaces as the emulated hosts (`netns.Hosts`) use them:
running `ip`/`nft` with one clear error, listing namespaces and their processes, killing
what a namespace holds, and removing what a run (or a crashed run: its pid is dead) left.
Every name starts with BASE, so nothing here touches namespaces it did not make."""
from __future__ import annotations

import itertools
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence

SUBNET = "198.18.0.0/24"   # from the benchmarking range 198.18.0.0/15 (RFC 2544): never a real network
BASE = "sm-"               # every namespace this module makes starts with it
HUB = "hub"
BRIDGE = "br0"
IFACE = "eth0"
NFT_TABLE = "saim"         # `bridge saim` in the hub namespace
NFT_CHAIN = "cuts"
NOWHERE_MAC = "02:00:00:00:00:00"   # the fallback pair cut: a neighbour entry that reaches no host
_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
_STALE = re.compile(r"^sm-(\d+)-")
_counter = itertools.count()
_said: set[str] = set()


class NetnsError(RuntimeError):
    """A system command failed: the message names the command and what it said."""


def _say_once(key: str, msg: str, log: Callable[[str], None]) -> None:
    if key not in _said:
        _said.add(key)
        log(msg)


def _stderr(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def sh(argv: Sequence[str], what: str, *, input: str | None = None, check: bool = True,
       timeout: float = 30.0) -> str:
    """Run a system command; on failure raise one line: what we tried, the command, its error."""
    try:
        r = subprocess.run(list(argv), input=input, capture_output=True, text=True, timeout=timeout)
    except FileNotFoundError as e:
        raise NetnsError(f"{what}: {argv[0]} not found ({e})") from None
    except subprocess.TimeoutExpired:
        raise NetnsError(f"{what}: `{' '.join(argv)}` did not finish within {timeout} s") from None
    if check and r.returncode != 0:
        err = (r.stderr or r.stdout).strip().replace("\n", " | ")
        raise NetnsError(f"{what}: `{' '.join(argv)}` exited {r.returncode}: {err}")
    return r.stdout


def namespaces() -> list[str]:
    """Every named network namespace (`ip netns list`)."""
    out = sh(["ip", "netns", "list"], "listing network namespaces")
    return [line.split()[0] for line in out.splitlines() if line.strip()]


def ns_pids(ns: str) -> list[int]:
    """The processes inside namespace `ns` (none when it is gone)."""
    out = sh(["ip", "netns", "pids", ns], f"listing the processes of {ns}", check=False)
    return [int(x) for x in out.split() if x.isdigit()]


def _kill_all(pids: Sequence[int], sig: int = signal.SIGKILL) -> None:
    for pid in pids:
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            pass


def _alive(pid: int) -> bool:
    """True while the pid exists and is not a zombie (a zombie no longer holds its namespace)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


def _empty_namespace(ns: str, timeout: float = 5.0) -> list[int]:
    """SIGKILL everything in `ns` until nothing is left (or the deadline); returns survivors."""
    end = time.monotonic() + timeout
    while True:
        pids = [p for p in ns_pids(ns) if _alive(p)]
        if not pids or time.monotonic() > end:
            return pids
        _kill_all(pids)
        time.sleep(0.02)


def cleanup(prefix: str) -> list[str]:
    """Remove every namespace whose name starts with `prefix` (its bridge, veths and tbf go
    with it), after killing every process inside. For the leftovers of a crashed run;
    returns the namespaces removed. Errors are collected and raised at the end, once
    everything was tried."""
    if not prefix.startswith(BASE) or len(prefix) <= len(BASE):
        raise ValueError(f"cleanup prefix {prefix!r}: expected {BASE}<something> (not to remove others' namespaces)")
    gone, errors = [], []
    mine = sorted((n for n in namespaces() if n.startswith(prefix)), key=lambda n: n.endswith(HUB))  # hub last
    for ns in mine:
        if left := _empty_namespace(ns):
            errors.append(f"{ns}: processes {left} survived SIGKILL")
    for ns in mine:
        try:
            sh(["ip", "netns", "del", ns], f"removing namespace {ns}")
            gone.append(ns)
        except NetnsError as e:
            errors.append(str(e))
    if errors:
        raise NetnsError("; ".join(errors))
    return gone


def stale_prefixes() -> list[str]:
    """Prefixes `sm-<pid>-` of namespaces whose creating process is dead."""
    out = set()
    for ns in namespaces():
        if (m := _STALE.match(ns)) and not _alive(int(m.group(1))):
            out.add(m.group(0))
    return sorted(out)


def cleanup_stale() -> list[str]:
    """What crashed runs left (their pid is dead); a live run's namespaces are untouched."""
    return [ns for p in stale_prefixes() for ns in cleanup(p)]


def unavailable() -> str | None:
    """Why namespaced hosts cannot be made here (one line), or None when they can."""
    if not sys.platform.startswith("linux"):
        return f"network namespaces need Linux, not {sys.platform}"
    if os.geteuid() != 0:
        return "network namespaces need root (ip netns add)"
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2) on PATH"
    probe = f"{BASE}{os.getpid()}-probe"
    try:
        sh(["ip", "netns", "add", probe], "creating a probe namespace")
        try:
            sh(["ip", "-n", probe, "link", "add", "name", "pbr0", "type", "bridge"], "creating a bridge in it")
            sh(["ip", "-n", probe, "link", "add", "name", "pv0", "type", "veth", "peer", "name", "pv1"], "creating a veth pair")
        finally:
            sh(["ip", "netns", "del", probe], "removing the probe namespace", check=False)
    except NetnsError as e:
        return str(e)
    return None
