"""Mesh benchmark, all in one run so the figures share the machine's mood:
raw Zenoh pub/sub between two processes (the baseline), one EA through the mesh,
report-to-alert latency at 1,000 events/s, and the whole battalion through one
peer per unit at max speed. Writes bench/results/mesh.json."""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import uuid
from pathlib import Path

import zenoh

from . import messages as M
from . import scenario as S
from .mesh import Proc, start_peer, up
from .runner import run
from .zconf import config, free_port

ROOT = Path(__file__).resolve().parents[1]
BLOCK = zenoh.CongestionControl.BLOCK


def role_pub(endpoint: str, n: int, scenario: str) -> None:
    sc = S.load(scenario)
    wire = [M.encode(e) for e in sc.events[:n]]
    with zenoh.open(config([endpoint], [])) as s:
        pub = s.declare_publisher("bench/raw/data", congestion_control=BLOCK)
        print("ready", flush=True)
        sys.stdin.readline()     # the subscriber is up: go
        deadline = time.monotonic() + 30
        while not pub.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)     # wait for the subscriber's declaration to reach us
        for w in wire:
            pub.put(w)
        pub.put(b"END")
        sys.stdin.readline()


def role_sub(endpoint: str) -> None:
    with zenoh.open(config([], [endpoint])) as s:
        sub = s.declare_subscriber("bench/raw/data", zenoh.handlers.FifoChannel(1_000_000))
        print("ready", flush=True)
        n, t0 = 0, None
        while True:
            smp = sub.recv()
            b = smp.payload.to_bytes()
            if t0 is None:
                t0 = time.perf_counter()
            if b == b"END":
                break
            M.decode(b)          # the same decoding a peer does
            n += 1
        dt = time.perf_counter() - t0
        print("result " + json.dumps({"msgs": n, "s": dt}), flush=True)


def raw_baseline(scenario: str, n: int) -> float:
    ep = f"tcp/127.0.0.1:{free_port()}"
    pub = subprocess.Popen([sys.executable, "-m", "saim_mesh.bench_mesh", "--role", "pub", "--endpoint", ep,
                            "--n", str(n), "--scenario", scenario], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                           text=True)
    try:
        assert pub.stdout.readline().startswith("ready")
        sub = Proc("sub", [sys.executable, "-m", "saim_mesh.bench_mesh", "--role", "sub", "--endpoint", ep])
        try:
            sub.wait_for("ready", 30)
            pub.stdin.write("go\n")
            pub.stdin.flush()
            res = json.loads(sub.wait_for("result ", 300)[7:])
        finally:
            sub.stop()
        pub.stdin.write("done\n")
        pub.stdin.flush()
        pub.wait(30)
    finally:
        if pub.poll() is None:
            pub.kill()
            pub.wait()
    return res["msgs"] / res["s"]


def one_peer(scenario: str, unit: str, speed: str, until: float | None, tmp: Path) -> dict:
    tmp.mkdir(parents=True, exist_ok=True)
    ep = f"tcp/127.0.0.1:{free_port()}"
    root = f"bench/{uuid.uuid4().hex[:8]}"
    args = [sys.executable, "-m", "saim_mesh", "replay", scenario, "--listen", ep, "--root", root, "--speed", speed,
            "--linger", "5", "--wait-peers", unit] + (["--until", str(until)] if until else [])
    rp = Proc("replay", args)
    procs = [rp]
    try:
        rp.wait_for("ready", 60)
        p = start_peer(scenario, unit, ep, root, tmp / f"{unit}.jsonl")
        procs.append(p)
        return json.loads(p.wait_for("summary ", 600)[8:])
    finally:
        for x in procs:
            x.stop()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--role", choices=["pub", "sub"])
    ap.add_argument("--endpoint")
    ap.add_argument("--n", type=int, default=77_000)
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion"))
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "mesh.json"))
    ap.add_argument("--tmp", default=str(ROOT / "out" / "bench-mesh"))
    a = ap.parse_args(argv)
    if a.role == "pub":
        role_pub(a.endpoint, a.n, a.scenario)
        return 0
    if a.role == "sub":
        role_sub(a.endpoint)
        return 0
    tmp = Path(a.tmp)
    tmp.mkdir(parents=True, exist_ok=True)
    sc = S.load(a.scenario)
    n_ev = len(sc.events)
    raw = raw_baseline(a.scenario, min(a.n, n_ev))
    print(f"raw zenoh pub/sub + decode, 2 processes: {raw:,.0f} msgs/s", flush=True)
    bn = one_peer(a.scenario, "BN", "max", None, tmp / "ea")
    ea_rate = n_ev / bn["active_s"]
    print(f"one EA (BN) through the mesh: {ea_rate:,.0f} events/s", flush=True)
    speed = 1000.0 / (n_ev / sc.duration_s)      # scenario speed that makes 1,000 events/s
    lat = one_peer(a.scenario, "BN", f"{speed:.3f}", 1500.0, tmp / "lat")
    print(f"latency at 1,000 events/s: tick {lat['tick_latency_ms']}, alert {lat['alert_latency_ms']}", flush=True)
    res = up(a.scenario, None, tmp / "battalion", "max")
    peers = res["peers"]
    inproc = {ea.owner: [json.dumps(x.to_json_dict(), sort_keys=True) for x in ea.alerts]
              for ea in run(sc, list(peers))}
    same = {u: [json.dumps(json.loads(line), sort_keys=True) for line in open(tmp / "battalion" / f"{u}.jsonl")
                if json.loads(line)["category"] != "system-problem"] == inproc[u] for u in peers}
    sens_path = str(Path(a.scenario).parent / "battalion-sensors")
    sens_same = None
    if Path(sens_path).is_dir():   # the same through fusion peers: alerts from fused tracks
        rs = up(sens_path, None, tmp / "battalion-sensors", "max")
        ssc = S.load(sens_path)
        want = {ea.owner: [json.dumps(x.to_json_dict(), sort_keys=True) for x in ea.alerts]
                for ea in run(ssc, list(rs["peers"]))}
        sens_same = {u: [json.dumps(json.loads(line), sort_keys=True)
                         for line in open(tmp / "battalion-sensors" / f"{u}.jsonl")
                         if json.loads(line)["category"] != "system-problem"] == want[u] for u in rs["peers"]}
    out = {
        "raw_msgs_per_s": round(raw), "ea_events_per_s": round(ea_rate),
        "ea_share_of_raw": round(ea_rate / raw, 3),
        "latency_p50_ms": lat["tick_latency_ms"].get("p50"), "latency_p99_ms": lat["tick_latency_ms"].get("p99"),
        "alert_latency_ms": lat["alert_latency_ms"], "latency_events_per_s": 1000,
        "battalion_wall_s": round(res["wall_s"], 2), "peers": len(peers),
        "peak_rss_mb": max(s["peak_rss_mb"] for s in peers.values()),
        "peak_rss_mb_by_peer": {u: s["peak_rss_mb"] for u, s in peers.items()},
        "alerts_equal_in_process": same, "events": n_ev,
        "sensors_wall_s": round(rs["wall_s"], 2) if sens_same is not None else None,
        "sensors_alerts_equal_in_process": sens_same,
        "targets": {"ea_share_of_raw": 0.4, "latency_p99_ms": 20, "battalion_wall_s": 60, "peak_rss_mb": 200},
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps({k: out[k] for k in ("raw_msgs_per_s", "ea_events_per_s", "latency_p50_ms", "latency_p99_ms",
                                          "battalion_wall_s", "peers", "peak_rss_mb")}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
