"""Mesh benchmark, all in one run so the figures share the machine's mood:
raw Zenoh pub/sub between two processes (the baseline: the replay's real keys and
batches into the BN peer's real subscriptions, unpacked, filtered and decoded as a
peer does), the in-process EA on the same events, one EA through the mesh and its
share of the in-process rate (the best of three interleaved rounds of each),
report-to-alert latency at 1,000 events/s, and the whole battalion through one peer
per unit at max speed with peak PSS and RSS per peer. Writes bench/results/mesh.json."""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import uuid
from pathlib import Path

import zenoh

from dissemination.coarse import coarse
from dissemination.exact import exact
from dissemination.interest import Interest
from dissemination.keyspace import KeySpace

from . import batch as B
from . import messages as M
from . import scenario as S
from . import wire as W
from . import zygote
from .bench_ea import feed
from .procstat import Sampler
from .mesh import Proc, start_peer, up
from .proc import leaf_env
from .runner import config_for, make_ea, run
from .zconf import config, free_port

RAW_ROOT = "bench/raw"

ROOT = Path(__file__).resolve().parents[1]
BLOCK = zenoh.CongestionControl.BLOCK


def peer_interest(sc, unit: str, root: str) -> tuple[set[str], set[str]]:
    """The fine interest and the Zenoh subscriptions a peer for `unit` starts with."""
    cfg = config_for(sc, unit, None)
    ea = make_ea(sc, unit, cfg, sinks=[])
    ea.start(0.0)
    dis = cfg["dissemination"]
    ks = KeySpace.of(sc, root)
    fine = Interest(ks, dis["radius_m"], int(dis["block_share"])).keys(ea.domain) - {ks.clock()}
    to = sc.taskorg
    return fine, coarse(fine, root, B.groups_of(root), [to.path(u) for u in to.units])


def role_pub(endpoint: str, n: int, scenario: str) -> None:
    """The replay's stream on its real keys: batched per group and 2 s tick, the rest single."""
    sc = S.load(scenario)
    ks = KeySpace.of(sc, RAW_ROOT)
    evs = sc.events[:n]
    script = [(ev, ks.key(ev, sc.taskorg, sc.projection), M.encode(ev)) for ev in evs]
    with zenoh.open(config([endpoint], [])) as s:
        pubs = {k: s.declare_publisher(k, congestion_control=BLOCK) for _, k, _ in script}
        end = s.declare_publisher(f"{RAW_ROOT}/ord/bench-end", congestion_control=BLOCK)
        batcher = B.Batcher(s, B.groups_of(RAW_ROOT))
        print("ready", flush=True)
        sys.stdin.readline()     # the subscriber is up: go
        deadline = time.monotonic() + 30
        while not end.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)     # wait for the subscriber's declarations to reach us
        next_tick = W.TICK_S
        for seq, (ev, key, payload) in enumerate(script, 1):
            if ev.t >= next_tick:
                batcher.flush()
                next_tick = (ev.t // W.TICK_S + 1) * W.TICK_S
            if not batcher.add(key, seq, payload):
                pubs[key].put(payload, attachment=seq.to_bytes(8, "big"))
        batcher.flush()
        end.put(b"END")
        sys.stdin.readline()


def role_sub(endpoint: str, subs_path: str) -> None:
    """The BN peer's subscriptions; each sample unpacked, filtered and decoded as the peer does."""
    spec = json.loads(Path(subs_path).read_text())
    want = exact(spec["fine"], RAW_ROOT)
    groups = B.groups_of(RAW_ROOT)
    gate = W.Gate(1e9)
    with zenoh.open(config([], [endpoint])) as s:
        subs = [s.declare_subscriber(k, zenoh.handlers.FifoChannel(1_000_000)) for k in spec["coarse"]]
        print("ready", flush=True)
        n, samples, t0, done = 0, 0, None, False
        while not done:
            got = False
            for sub in subs:
                while (smp := sub.try_recv()) is not None:
                    got = True
                    b = smp.payload.to_bytes()
                    t0 = t0 or time.perf_counter()
                    if b == b"END":
                        done = True
                        break
                    samples += 1
                    key = str(smp.key_expr)
                    items = B.unpack(gate, groups, b, key) if groups.is_batch(key) else [(0, key, b)]
                    for _, k, p in items:
                        if want(k) and gate.data(p, k) is not None:
                            n += 1
            if not got:
                time.sleep(0.0005)   # nothing queued: poll again (a benchmark loop, not a barrier)
        dt = time.perf_counter() - t0
        print("result " + json.dumps({"msgs": n, "samples": samples, "s": dt}), flush=True)


def raw_baseline(scenario: str, n: int, subs_path: Path) -> dict:
    ep = f"tcp/127.0.0.1:{free_port()}"
    pub = subprocess.Popen([sys.executable, "-m", "saim_mesh.bench_mesh", "--role", "pub", "--endpoint", ep,
                            "--n", str(n), "--scenario", scenario], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                           text=True)
    try:
        assert pub.stdout.readline().startswith("ready")
        sub = Proc("sub", [sys.executable, "-m", "saim_mesh.bench_mesh", "--role", "sub", "--endpoint", ep,
                           "--subs", str(subs_path)])
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
    return res


def one_peer(scenario: str, unit: str, speed: str, until: float | None, tmp: Path) -> dict:
    tmp.mkdir(parents=True, exist_ok=True)
    ep = f"tcp/127.0.0.1:{free_port()}"
    root = f"bench/{uuid.uuid4().hex[:8]}"
    args = [sys.executable, "-m", "saim_mesh", "replay", scenario, "--listen", ep, "--root", root, "--speed", speed,
            "--linger", "5", "--wait-peers", unit] + (["--until", str(until)] if until else [])
    rp = Proc("replay", args, env=leaf_env())   # as `mesh.start_replay` has it
    procs = [rp]
    try:
        rp.wait_for("ready", 60)
        p = start_peer(scenario, unit, ep, root, tmp / f"{unit}.jsonl")
        procs.append(p)
        return json.loads(p.wait_for("summary ", 600)[8:])
    finally:
        for x in procs:
            x.stop()


def in_process(sc, unit: str) -> float:
    """Seconds for the in-process EA (the peer's configuration) to take every event."""
    return feed(make_ea(sc, unit, config_for(sc, unit, None), sinks=[]), sc)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--role", choices=["pub", "sub"])
    ap.add_argument("--endpoint")
    ap.add_argument("--subs")
    ap.add_argument("--n", type=int, default=77_000)
    ap.add_argument("--rounds", type=int, default=3, help="in-process and one-peer runs, interleaved; the best of each")
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion"))
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "mesh.json"))
    ap.add_argument("--tmp", default=str(ROOT / "out" / "bench-mesh"))
    a = ap.parse_args(argv)
    if a.role == "pub":
        role_pub(a.endpoint, a.n, a.scenario)
        return 0
    if a.role == "sub":
        role_sub(a.endpoint, a.subs)
        return 0
    tmp = Path(a.tmp)
    tmp.mkdir(parents=True, exist_ok=True)
    sc = S.load(a.scenario)
    n_ev = len(sc.events)
    fine, zsubs = peer_interest(sc, "BN", RAW_ROOT)
    subs_path = tmp / "bn-subs.json"
    subs_path.write_text(json.dumps({"fine": sorted(fine), "coarse": sorted(zsubs)}))
    raw_res = raw_baseline(a.scenario, min(a.n, n_ev), subs_path)
    raw = raw_res["msgs"] / raw_res["s"]
    print(f"raw zenoh pub/sub + unpack + filter + decode, BN's {len(zsubs)} subscriptions, 2 processes: "
          f"{raw:,.0f} msgs/s ({raw_res['samples']:,} samples for {raw_res['msgs']:,} messages)", flush=True)
    rounds = []
    for i in range(a.rounds):   # interleaved, so both sides see the same moments of this noisy machine
        t_in = in_process(sc, "BN")
        r = one_peer(a.scenario, "BN", "max", None, tmp / "ea")
        rounds.append({"in_process_s": round(t_in, 3), "ea_active_s": r["active_s"],
                       "share": round(t_in / r["active_s"], 3), "summary": r})
        print(f"round {i + 1}: in-process {t_in:.2f} s, EA peer {r['active_s']:.2f} s active: "
              f"share {t_in / r['active_s']:.2f}", flush=True)
    inproc_rate = n_ev / min(x["in_process_s"] for x in rounds)   # the best of each side
    print(f"in-process EA (BN), same events: {inproc_rate:,.0f} events/s", flush=True)
    bn = min((x["summary"] for x in rounds), key=lambda r: r["active_s"])
    ea_rate = n_ev / bn["active_s"]
    print(f"one EA (BN) through the mesh: {ea_rate:,.0f} events/s = {ea_rate / inproc_rate:.2f} of in-process; "
          f"{bn['samples']:,} samples ({bn['batches']:,} batches) for {bn['entries'] + bn['samples'] - bn['batches']:,} "
          f"messages, {bn['dropped']:,} dropped by the exact filter, {bn['zenoh_subscriptions']} Zenoh subscriptions "
          f"for {bn['subscriptions']} fine key expressions", flush=True)
    speed = 1000.0 / (n_ev / sc.duration_s)      # scenario speed that makes 1,000 events/s
    lat = one_peer(a.scenario, "BN", f"{speed:.3f}", None, tmp / "lat")   # a peer takes no early end tick
    print(f"latency at 1,000 events/s: tick {lat['tick_latency_ms']}, alert {lat['alert_latency_ms']}", flush=True)
    zyg = lambda: {"zygote": zygote._shared.p.pid} if zygote._shared is not None and zygote._shared.alive() else {}
    with Sampler(tmp / "battalion" / "pids.json", every_s=0.25, extra=zyg) as mem:
        res = up(a.scenario, None, tmp / "battalion", "max")
    peers = res["peers"]
    ea_mem = {u: mem.peak[u] for u in peers if u in mem.peak}
    print(f"battalion: peak PSS per EA peer {max(m['pss_mb'] for m in ea_mem.values()):.1f} MB "
          f"(RSS {max(m['rss_mb'] for m in ea_mem.values()):.1f} MB)", flush=True)
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
    flow = {u: {k: s.get(k) for k in ("zenoh_subscriptions", "subscriptions", "samples", "batches", "entries",
                                       "dropped", "messages")} for u, s in peers.items()}
    out = {
        "raw_msgs_per_s": round(raw), "raw_subscriptions": len(zsubs), "raw_samples": raw_res["samples"],
        "raw_messages": raw_res["msgs"],
        "in_process_events_per_s": round(inproc_rate), "ea_events_per_s": round(ea_rate),
        "ea_share_of_in_process": round(ea_rate / inproc_rate, 3),   # best peer round against best in-process
        "ea_rounds": [{k: v for k, v in x.items() if k != "summary"} for x in rounds],
        "ea_share_median_round": sorted(x["share"] for x in rounds)[len(rounds) // 2],
        "ea_share_of_raw": round(ea_rate / raw, 3),
        "ea_flow": {k: bn.get(k) for k in ("zenoh_subscriptions", "subscriptions", "samples", "batches", "entries",
                                            "dropped", "messages")},
        "ea_samples_per_event": round(bn["samples"] / n_ev, 4),
        "ea_stage_s": bn.get("stage_s"),   # where the peer's time went: waiting, receiving, ticks (the EA), interest
        "ea_stage_cpu_s": bn.get("stage_cpu_s"),   # the main thread's CPU time in those stages
        "ea_ctx_switches": bn.get("ctx_switches"), "ea_cpu_s": bn.get("cpu_s"),
        "ea_active_s": bn["active_s"], "in_process_s": round(n_ev / inproc_rate, 3),
        "latency_p50_ms": lat["tick_latency_ms"].get("p50"), "latency_p99_ms": lat["tick_latency_ms"].get("p99"),
        "alert_latency_ms": lat["alert_latency_ms"], "latency_events_per_s": 1000,
        "battalion_wall_s": round(res["wall_s"], 2), "peers": len(peers),
        "peak_rss_mb": max(s["peak_rss_mb"] for s in peers.values()),
        "peak_rss_mb_by_peer": {u: s["peak_rss_mb"] for u, s in peers.items()},
        "peak_pss_mb_per_ea_peer": max(m["pss_mb"] for m in ea_mem.values()),
        "peak_pss_mb_per_ea_peer_any": max(m["pss_mb_any"] for m in ea_mem.values()),   # peers leaving included
        "memory_by_process": mem.peak_memory, "flow_by_peer": flow,
        "alerts_equal_in_process": same, "events": n_ev,
        "sensors_wall_s": round(rs["wall_s"], 2) if sens_same is not None else None,
        "sensors_alerts_equal_in_process": sens_same,
        "targets": {"ea_share_of_in_process": 0.6, "peak_pss_mb_per_ea_peer": 40, "latency_p99_ms": 20,
                    "battalion_wall_s": 60, "peak_rss_mb": 200},
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps({k: out[k] for k in ("raw_msgs_per_s", "in_process_events_per_s", "ea_events_per_s",
                                          "ea_share_of_in_process", "latency_p50_ms", "latency_p99_ms",
                                          "battalion_wall_s", "peers", "peak_pss_mb_per_ea_peer", "peak_rss_mb")}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
