"""Soak run: the battalion (with sensors, so fusion nodes too) through one secure peer
per unit under `mesh up`, while processes are killed at random and restarted by the
supervisor, a junk publisher floods the keys its identity may use, and a forged-order
publisher tries to abort the battalion's plan. Writes bench/results/soak.json: what
was sent, rejected, killed and restarted, alerts lost (must be 0), peak RSS per peer,
and whether every peer's alerts equal the fault-free (in-process) run's.

Not part of CI's default run: `scripts/soak` (about 3-6 minutes here)."""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import threading
import time
from pathlib import Path

import zenoh

from . import messages as M
from . import scenario as S
from . import wire as W
from .alertlog import alert_key
from .scenario import mesh_units
from .proc import Proc, clean_env, py
from .runner import run
from .zconf import config

ROOT = Path(__file__).resolve().parents[1]
BLOCK = zenoh.CongestionControl.BLOCK


def _endpoint(out: Path, timeout: float = 120.0) -> str:
    """The replay's listen endpoint, from its command line in the mesh's pid file."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        log = out / "logs" / "replay.log"
        if (out / "pids.json").exists() and log.exists() and b"start" in log.read_bytes():
            pid = json.loads((out / "pids.json").read_text())["replay"]
            args = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
            return args[args.index(b"--listen") + 1].decode()
        time.sleep(0.1)
    raise TimeoutError("the mesh's replay never started")


class Attackers(threading.Thread):
    """Junk on the keys a legitimate identity may use (counted as rejects by the
    peers) and forged orders from an identity that may not give them (dropped by
    Zenoh's access control), until stopped."""

    def __init__(self, sc, out: Path, root: str, rate_hz: float = 200.0):
        super().__init__(daemon=True)
        self.sc, self.out, self.root, self.rate = sc, out, root, rate_hz
        self.stop_ev = threading.Event()
        self.sent = {"junk": 0, "forged_orders": 0}
        self.error: str | None = None

    def run(self) -> None:
        try:
            ep = _endpoint(self.out)
            pki = self.out / "pki"
            rnd = random.Random(1)
            junk_conf = config(["tls/127.0.0.1:0"], [ep], pki=pki, name="ea.C", sc=self.sc, root=self.root)
            forge_conf = config(["tls/127.0.0.1:0"], [ep], pki=pki, name="ea.A3", sc=self.sc, root=self.root)
            with zenoh.open(junk_conf) as junk, zenoh.open(forge_conf) as forge:
                order = M.encode(M.Order(1000.0, "abort-plan", "main", "BN"))
                while not self.stop_ev.wait(1.0 / self.rate):
                    k = rnd.choice(("health/C", "ack/C/x", "alert/C/contact", "msn/C/C-move"))
                    payload = rnd.choice((rnd.randbytes(rnd.randint(1, 64)), b"\xc1",
                                          W.encode(W.make(W.Tick, t=1e8, n=1, seq=1, end=True)),
                                          b"\x00" * 100_000))
                    junk.put(f"{self.root}/{k}", payload)
                    self.sent["junk"] += 1
                    if self.sent["junk"] % 10 == 0:
                        forge.put(f"{self.root}/ord/BN", order, congestion_control=BLOCK)
                        self.sent["forged_orders"] += 1
        except Exception as e:   # the soak reports it; the mesh run goes on
            self.error = f"{type(e).__name__}: {e}"


def chaos(out: Path, victims: list[str], kills: int, every_s: float, rnd: random.Random, done) -> list[dict]:
    """Kill a random victim every `every_s` seconds (SIGKILL), `kills` times."""
    killed = []
    while len(killed) < kills and not done():
        time.sleep(every_s * (0.5 + rnd.random()))
        if done():
            break
        name = rnd.choice(victims)
        try:
            pid = json.loads((out / "pids.json").read_text())[name]
            os.kill(pid, signal.SIGKILL)
            killed.append({"process": name, "pid": pid, "wall_s": round(time.monotonic(), 1)})
        except (ProcessLookupError, KeyError, ValueError, OSError):
            continue
    return killed


def _rss_kb(pid: int) -> int:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion-sensors"))
    ap.add_argument("--kills", type=int, default=8)
    ap.add_argument("--every", type=float, default=6.0, help="mean wall seconds between kills")
    ap.add_argument("--speed", default="40", help="replay speed (a factor, or max)")
    ap.add_argument("--out", default=str(ROOT / "out" / "soak"))
    ap.add_argument("--result", default=str(ROOT / "bench" / "results" / "soak.json"))
    ap.add_argument("--seed", type=int, default=11)
    a = ap.parse_args(argv)
    sc = S.load(a.scenario, events=False)
    units = mesh_units(sc)
    groups = sorted(sc.meta.get("fusion", {}).get("groups", {}))
    out = Path(a.out)
    root = f"soak/{os.getpid()}"
    t0 = time.monotonic()
    mesh = Proc("mesh", [*py(), "mesh", "up", a.scenario, "--replay", "--out-dir", str(out), "--speed", a.speed,
                         "--root", root], env=clean_env(), log_dir=out.parent)
    finished = lambda: mesh.exited() is not None
    attackers = Attackers(sc, out, root)
    attackers.start()
    rss: dict[str, int] = {}
    samples: dict[str, list[int]] = {}

    def sample() -> None:
        while not finished():
            try:
                for name, pid in json.loads((out / "pids.json").read_text()).items():
                    kb = _rss_kb(pid)
                    rss[name] = max(rss.get(name, 0), kb)
                    samples.setdefault(name, []).append(kb)
            except (OSError, ValueError):
                pass
            time.sleep(1.0)
    threading.Thread(target=sample, daemon=True).start()
    _endpoint(out)
    killed = chaos(out, [*units, *(f"fusion-{g}" for g in groups)], a.kills, a.every, random.Random(a.seed),
                   finished)
    code = mesh.p.wait(1800)
    attackers.stop_ev.set()
    attackers.join(10)
    summary = json.loads((out / "summary.json").read_text())
    print("computing the fault-free run in process ...", flush=True)
    want = {ea.owner: [alert_key(x.to_json_dict()) for x in ea.alerts] for ea in run(S.load(a.scenario), units)}
    equal, lost, extra = {}, {}, {}
    for u in units:
        got = [alert_key(x) for x in map(json.loads, open(out / f"{u}.jsonl")) if x["category"] != "system-problem"]
        equal[u] = got == want[u]
        lost[u] = len([k for k in want[u] if k not in got])
        extra[u] = len([k for k in got if k not in want[u]])
    peers = summary["peers"]
    flat = {u: (samples[u][len(samples[u]) // 2:] if len(samples.get(u, [])) > 4 else []) for u in units}
    res = {
        "scenario": Path(a.scenario).name, "peers": len(units), "fusion_nodes": len(groups),
        "mesh_exit_code": code, "secure": summary["secure"], "wall_s": round(time.monotonic() - t0, 1),
        "messages_sent": {"junk": attackers.sent["junk"], "forged_orders": attackers.sent["forged_orders"],
                          "replay_events": next((int(x.split("events=")[1].split()[0])
                                                 for x in summary["replay"] if x.startswith("end events=")), None)},
        "attacker_error": attackers.error,
        "rejects_counted_by_peers": sum(p.get("bad_messages", 0) for p in peers.values()),
        "rejects_by_kind": _sum_kinds(p.get("rejects", {}) for p in peers.values()),
        "killed": killed, "crashes_seen": sum(1 for e in summary["events"] if "exit_code" in e),
        "restarts": sum(1 for e in summary["events"] if "restarted" in e), "given_up": summary["given_up"],
        "late_alerts": {u: p.get("late_alerts", 0) for u, p in peers.items() if p.get("late_alerts")},
        "alerts_lost": sum(lost.values()), "alerts_extra": sum(extra.values()),
        "alerts_equal_fault_free": all(equal.values()), "unequal_peers": sorted(u for u, ok in equal.items() if not ok),
        "peak_rss_mb": {u: round(kb / 1024, 1) for u, kb in sorted(rss.items())},
        "rss_second_half_growth_mb": {u: round((max(v) - min(v)) / 1024, 1) for u, v in flat.items() if v},
    }
    Path(a.result).parent.mkdir(parents=True, exist_ok=True)
    Path(a.result).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps({k: v for k, v in res.items() if k not in ("killed", "peak_rss_mb")}, indent=1))
    return 0 if res["alerts_lost"] == 0 and res["alerts_equal_fault_free"] and code == 0 else 1


def _sum_kinds(dicts) -> dict:
    out: dict[str, int] = {}
    for d in dicts:
        for k, v in d.items():
            out[k] = out.get(k, 0) + v
    return dict(sorted(out.items()))


if __name__ == "__main__":
    raise SystemExit(main())
