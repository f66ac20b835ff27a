"""The brigade on routers across emulated radio links, on this machine, all in one run:

1. `mesh up --topology` (one router per battalion command post and one at brigade,
   each router link through `saim-mesh link`) at max speed with an EA peer per unit:
   wall time against scenario time, CPU and peak PSS/RSS per process, bytes per
   router link, and every peer's alerts against the in-process run's;
2. the flood baseline in the same run: the same routers, links and replay with one
   subscriber to everything behind each router (what each link would carry if every
   report went everywhere), counted per key family;
3. report-to-alert latency at 1x over the first minutes of the scenario.

Writes bench/results/scale.json.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
import uuid
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import zenoh

from saim_mesh.net import routed
from saim_mesh.net import topology as T
from saim_mesh.mesh import Supervisor, mesh_units, start_replay, up
from saim_mesh.proc import Proc, clean_env
from .procstat import Sampler

from . import ROOT


def _inproc(args: tuple[str, list[str]]) -> dict[str, list[str]]:
    from saim_mesh import scenario as S
    from saim_mesh.runner import run
    scenario, units = args
    return {ea.owner: [json.dumps(a.to_json_dict(), sort_keys=True) for a in ea.alerts]
            for ea in run(S.load(scenario), units)}


def in_process(scenario: str, units: list[str], workers: int = 2) -> dict[str, list[str]]:
    """Every unit's alerts from the in-process run (units split over `workers` processes)."""
    chunks = [units[i::workers] for i in range(workers)]
    out: dict[str, list[str]] = {}
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as ex:
        for part in ex.map(_inproc, [(scenario, c) for c in chunks if c]):
            out.update(part)
    return out


def plan_lines(path: Path) -> list[str]:
    """A peer's alerts as the in-process run raises them (no system notes, no late marks)."""
    out = []
    for line in open(path):
        a = json.loads(line)
        if a["category"] == "system-problem":
            continue
        for k in ("late", "cut_off"):
            a["details"].pop(k, None)
        out.append(json.dumps(a, sort_keys=True))
    return out


def role_tap(connect: str, root: str, conf_args: list[str]) -> None:
    """Subscribe to everything behind one router and count it per key family until SIGTERM."""
    from saim_mesh.zconf import config
    conf = config(None, [connect], mode="client")
    counts: Counter = Counter()
    nbytes: Counter = Counter()
    n = len(root) + 1

    def take(s):
        fam = str(s.key_expr)[n:].split("/", 1)[0]
        counts[fam] += 1
        nbytes[fam] += len(s.payload.to_bytes())
    stop = [False]
    signal.signal(signal.SIGTERM, lambda *_: stop.__setitem__(0, True))
    with zenoh.open(conf) as s:
        sub = s.declare_subscriber(f"{root}/**", take)
        print("tap ready", flush=True)
        while not stop[0]:
            time.sleep(0.1)
        sub.undeclare()
    print("tap " + json.dumps({"messages": dict(counts), "bytes": dict(nbytes)}), flush=True)


def flood(scenario: str, out: Path, link: dict) -> dict:
    """Routers, links and the replay (no EA peers) with a subscriber to everything behind
    each router: what a flood would put on each link, in the same run as the real thing."""
    from saim_mesh import scenario as S
    sc = S.load(scenario, events=False)
    out.mkdir(parents=True, exist_ok=True)
    (out / "logs").mkdir(exist_ok=True)
    topo = T.derive(sc.taskorg)
    root = f"bench/{uuid.uuid4().hex[:8]}"
    sup = Supervisor(lambda *a, **k: None, 0, pids_path=out / "pids.json")
    try:
        eps, link_files, resolved = routed.start(scenario, topo, out, root, sup, None, link)
        taps = {n: sup.add(Proc(f"tap-{n}", [sys.executable, "-m", "benchmarks.scale", "--role", "tap",
                                             "--connect", ep, "--root", root], env=clean_env(),
                                log_dir=out / "logs")) for n, ep in eps.items()}
        for p in taps.values():
            p.wait_for("tap ready", 60)
        t0 = time.monotonic()
        rp = sup.add(start_replay(scenario, "", root, [], "max", linger=0, log_dir=out / "logs",
                                  net=["--mode", "client", "--topology", str(resolved)]))
        rp.wait_for("end ", 3600)
        wall = time.monotonic() - t0
        rp.p.wait(60)
        for p in taps.values():
            p.p.send_signal(signal.SIGTERM)
        got = {n: json.loads(p.wait_for("tap {", 60)[4:]) for n, p in taps.items()}
    finally:
        sup.stop()
    return {"wall_s": round(wall, 1), "links": routed.link_stats(link_files), "received_behind_router": got}


def link_classes(trace_dir: Path, topo: T.Topology, taskorg, units: list[str]) -> dict:
    """Messages and payload bytes per router link, direction and key family, as the
    receivers saw them: a message crossed a link downwards when a peer below it took it
    from the wire and it entered above (its source's router is on the other side), and
    upwards the other way round. Each is counted once per link however many peers
    below took it (a router forwards it once)."""
    import numpy as np
    tr = np.load(trace_dir / "replay-trace.npz")
    src_names, fams = [str(x) for x in tr["sources"]], [str(x) for x in tr["families"]]
    recv = {u: np.fromfile(trace_dir / f"{u}.recv", dtype=np.uint32) for u in units
            if (trace_dir / f"{u}.recv").exists()}
    where = {u: topo.router_of(u, taskorg) for u in recv}
    out = {}
    for lower, upper in topo.links():
        side = topo.side((lower, upper))
        inside = np.array([n in side for n in src_names])
        row = {}
        for direction, takers, from_inside in (("down", [u for u in recv if where[u] in side], False),
                                               ("up", [u for u in recv if where[u] not in side], True)):
            seqs = np.unique(np.concatenate([recv[u] for u in takers])) if takers else np.zeros(0, np.uint32)
            seqs = seqs[seqs < len(tr["src"])]
            seqs = seqs[inside[tr["src"][seqs]] == from_inside]
            fam = tr["fam"][seqs]
            row[direction] = {fams[i]: {"messages": int((fam == i).sum()), "bytes": int(tr["nbytes"][seqs][fam == i].sum())}
                              for i in np.unique(fam).tolist()}
        out[f"{lower}->{upper}"] = row
    return out


def first_minutes(scenario: str, seconds: float, out: Path) -> str:
    """A copy of the scenario cut at `seconds` (its events and duration): a peer takes the
    end tick only at its scenario's end, so the 1x latency run needs a scenario that ends."""
    import gzip
    import shutil
    src, out = Path(scenario), Path(out)
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    for f in src.iterdir():
        if f.name not in ("events.jsonl.gz", "scenario.json", "generated.json") and f.is_file():
            shutil.copy(f, out / f.name)
    meta = json.loads((src / "scenario.json").read_text())
    meta["duration_s"] = float(seconds)
    (out / "scenario.json").write_text(json.dumps(meta, indent=1))
    with gzip.open(src / "events.jsonl.gz", "rt") as fin, gzip.open(out / "events.jsonl.gz", "wt") as fout:
        for line in fin:
            if json.loads(line)["t"] > seconds:
                break
            fout.write(line)
    return str(out)


def _pcts(xs: list[float]) -> dict:
    if not xs:
        return {}
    ys = sorted(xs)
    return {"n": len(ys), "p50": ys[len(ys) // 2], "p99": ys[min(len(ys) - 1, int(0.99 * len(ys)))], "max": ys[-1]}


def _link_bytes(links: dict) -> dict:
    return {n: {"up_bytes": s["up"]["bytes"], "down_bytes": s["down"]["bytes"],
                "total_bytes": s["up"]["bytes"] + s["down"]["bytes"]} for n, s in links.items() if s}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--role", choices=["tap"])
    ap.add_argument("--connect")
    ap.add_argument("--root")
    ap.add_argument("--scenario", help="default: the brigade, generated on demand into out/scenarios")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "scale.json"))
    ap.add_argument("--tmp", default=str(ROOT / "out" / "bench-scale"))
    ap.add_argument("--latency-s", type=float, default=420.0,
                    help="scenario seconds run at 1x for latency (the brigade's first alerts come at 330 s)")
    ap.add_argument("--insecure", action="store_true")
    ap.add_argument("--skip", nargs="*", default=[], choices=["brigade", "flood", "latency", "inproc", "live"],
                    help="phases to leave out; with `brigade`, the others update the results already in --out")
    ap.add_argument("--live-only", action="store_true",
                    help="only the live mesh (a source per command post, no replay): its results into --out's `live`")
    a = ap.parse_args(argv)
    if a.role == "tap":
        role_tap(a.connect, a.root, [])
        return 0
    from saim_mesh import scenario as S
    from saim_mesh.ondemand import ensure
    scenario = a.scenario or str(ensure("brigade", ROOT / "out" / "scenarios"))
    tmp = Path(a.tmp)
    sc = S.load(scenario, events=False)
    units = mesh_units(sc)
    link = {"delay_ms": 0.0, "loss": 0.0}
    res_path = tmp / "brigade"
    print(f"brigade: {len(units)} EA peers, {len(sc.taskorg.entity_unit)} entities, "
          f"{sc.duration_s:.0f} s of scenario", flush=True)
    if a.live_only:
        out = json.loads(Path(a.out).read_text()) if Path(a.out).exists() else {}
        out["live"] = live_phase(scenario, tmp / "live", link, a.insecure, units)
        Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
        print(json.dumps(out["live"], indent=1))
        return 0
    if "brigade" in a.skip:   # update the other phases' results in place
        out = json.loads(Path(a.out).read_text())
        _other_phases(a, scenario, tmp, link, res_path, out, {u: None for u in out["processes"] if u in units})
        Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
        return 0
    trace = tmp / "trace"
    trace.mkdir(parents=True, exist_ok=True)
    for f in trace.glob("*"):
        f.unlink()
    os.environ["SAIM_TRACE"] = str(trace)   # peers and the replay say what they took from the wire
    from saim_mesh import zygote
    zyg = lambda: {"zygote": zygote._shared.p.pid} if zygote._shared is not None and zygote._shared.alive() else {}  # noqa
    with Sampler(res_path / "pids.json", extra=zyg) as smp:
        res = up(scenario, None, res_path, "max", topology="derive", link=link, insecure=a.insecure,
                 timeout=7200, echo=lambda *x, **k: print(*x, **{kk: v for kk, v in k.items() if kk == "flush"}))
    os.environ.pop("SAIM_TRACE", None)
    peers = res["peers"]
    procs = smp.report()
    for u, s in peers.items():   # a peer's own CPU count is exact (the sampler's misses its last second)
        procs.setdefault(u, {})["cpu_s"] = s.get("cpu_s", procs.get(u, {}).get("cpu_s"))
    replay_sum = next((json.loads(x[8:]) for x in res["replay"] if x.startswith("summary ")), {})
    out: dict = {
        "scenario": Path(scenario).name, "entities": len(sc.taskorg.entity_unit), "ea_peers": len(peers),
        "routers": len(res["topology"]["routers"]), "scenario_s": sc.duration_s,
        "events": replay_sum.get("events"), "wall_s": round(res["wall_s"], 1),
        "times_real_time": round(sc.duration_s / res["wall_s"], 1), "secure": res["secure"],
        "crashes": [e for e in res["events"] if "exit_code" in e], "given_up": res["given_up"],
        "links": _link_bytes(res["links"]), "processes": procs,
    }
    try:
        topo, _ = T.read_resolved(res_path / "topology.json")
        out["links_by_family"] = link_classes(trace, topo, sc.taskorg, sorted(peers))
    except (OSError, ValueError, KeyError) as e:   # a trace missing (a peer that died): say so, keep the rest
        out["links_by_family"] = {"error": f"{type(e).__name__}: {e}"}
    ea = {u: procs.get(u, {}) for u in peers}
    pss = [p["pss_mb"] for p in ea.values() if p.get("pss_mb")]
    out["ea_peer_pss_mb"] = {"max": max(pss, default=None), "mean": round(sum(pss) / len(pss), 1) if pss else None}
    # the same at any moment, the end of the run included, when peers leave and the last ones'
    # PSS takes over the departed ones' share of the pages they all mapped (procstat.py)
    out["ea_peer_pss_mb_any"] = {"max": max((p["pss_mb_any"] for p in ea.values() if p.get("pss_mb_any")),
                                            default=None)}
    out["ea_peer_rss_mb"] = {"max": max((p["rss_mb"] for p in ea.values() if p.get("rss_mb")), default=None)}
    out["cpu_s_total"] = round(sum(p.get("cpu_s") or 0 for p in procs.values()), 1)
    print(json.dumps({k: out[k] for k in ("wall_s", "times_real_time", "ea_peers", "events", "cpu_s_total",
                                          "ea_peer_pss_mb")}), flush=True)
    _other_phases(a, scenario, tmp, link, res_path, out, peers)
    out["targets"] = {"times_real_time": 10.0, "ea_peer_pss_mb": 40.0}
    out["machine"] = {"cores": os.cpu_count()}
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    return 0


def live_phase(scenario: str, tmp: Path, link: dict, insecure: bool, units: list[str],
               want: dict[str, list[str]] | None = None) -> dict:
    """The brigade as the mesh with no centre: a source per command post at max speed, a
    router per battalion command post, every EA depending only on what its interest needs;
    wall time, peak PSS per EA peer, bytes per router link, alerts against in-process."""
    from saim_mesh import zygote
    from saim_mesh.live.up import up as live_up
    zyg = lambda: {"zygote": zygote._shared.p.pid} if zygote._shared is not None and zygote._shared.alive() else {}  # noqa
    tmp.mkdir(parents=True, exist_ok=True)
    with Sampler(tmp / "pids.json", extra=zyg) as smp:
        res = live_up(scenario, units, tmp, "max", show=False, topology="derive", link=link, insecure=insecure,
                      timeout=7200, echo=lambda *x, **k: print(*x, flush=True))
    procs = smp.report()
    peers = res["peers"]
    sc_s = json.loads((tmp / "summary.json").read_text()).get("wall_s", res["wall_s"])
    from saim_mesh import scenario as S
    dur = S.load(scenario, events=False).duration_s
    pss = [procs.get(u, {}).get("pss_mb") for u in peers]
    pss = [x for x in pss if x]
    want = want if want is not None else in_process(scenario, sorted(peers))
    same = {u: plan_lines(tmp / f"{u}.jsonl") == want.get(u) for u in sorted(peers)}
    out = {"wall_s": round(sc_s, 1), "times_real_time": round(dur / sc_s, 1), "ea_peers": len(peers),
           "sources": res["sources"], "secure": res["secure"],
           "ea_peer_pss_mb": {"max": max(pss, default=None), "mean": round(sum(pss) / len(pss), 1) if pss else None},
           "ea_peers_within_40_mb": sum(1 for x in pss if x <= 40.0),
           "ea_peer_pss_mb_top": dict(sorted(((u, procs[u]["pss_mb"]) for u in peers if procs.get(u, {}).get("pss_mb")),
                                             key=lambda x: -x[1])[:5]),
           # a source declared lost and back in a fault-free run (held by pacing, starved of CPU)
           "rebuilds": sum(s.get("rebuilds", 0) for s in peers.values()),
           "links": _link_bytes(res.get("links") or {}),
           "alerts_equal_in_process": sum(same.values()), "alerts_differ": sorted(u for u, ok in same.items() if not ok),
           "gaps": sum(s.get("gaps", 0) for s in peers.values()),
           "lost": sorted({x for s in peers.values() for x in s.get("lost", {})}),
           "cpu_s_total": round(sum(p.get("cpu_s") or 0 for p in procs.values()), 1),
           "targets": {"times_real_time": 10.0, "ea_peer_pss_mb": 40.0, "alerts_equal_in_process": len(units)}}
    print(f"live: {out['times_real_time']}x real time, {out['alerts_equal_in_process']}/{len(same)} equal, "
          f"PSS max {out['ea_peer_pss_mb']['max']} MB", flush=True)
    return out


def _other_phases(a, scenario: str, tmp: Path, link: dict, res_path: Path, out: dict, peers: dict) -> None:
    """The flood baseline, 1x latency and the in-process comparison, as not skipped."""
    if "flood" not in a.skip:
        fl = flood(scenario, tmp / "flood", link)
        out["flood"] = {"wall_s": fl["wall_s"], "links": _link_bytes(fl["links"]),
                        "received_behind_router": fl["received_behind_router"]}
        narrow = sum(v["total_bytes"] for v in out["links"].values())
        wide = sum(v["total_bytes"] for v in out["flood"]["links"].values())
        out["link_bytes_share_of_flood"] = round(narrow / wide, 3) if wide else None
        print(f"router links: {narrow / 1e6:.1f} MB against {wide / 1e6:.1f} MB flooded", flush=True)
    if "latency" not in a.skip:   # report-to-alert at 1x over the first minutes
        cut = first_minutes(scenario, a.latency_s, tmp / "latency-scenario")
        lat = up(cut, None, tmp / "latency", "1", topology="derive", link=link, insecure=a.insecure,
                 timeout=a.latency_s + 600, echo=lambda *x, **k: None)
        xs = [v for s in lat["peers"].values() for v in s.get("alert_latencies_ms", [])]
        ticks = [s["tick_latency_ms"].get("p99") for s in lat["peers"].values() if s.get("tick_latency_ms")]
        out["latency_1x"] = {"scenario_s": a.latency_s, "alert_latency_ms": _pcts(xs),
                             "tick_latency_p99_ms_worst_peer": max(ticks, default=None)}
        print(f"1x: report-to-alert {out['latency_1x']['alert_latency_ms']}", flush=True)
    if "inproc" not in a.skip:
        want = in_process(scenario, sorted(peers))
        same = {u: plan_lines(res_path / f"{u}.jsonl") == want[u] for u in sorted(peers)}
        out["alerts_equal_in_process"] = all(same.values())
        out["alerts_differ"] = sorted(u for u, ok in same.items() if not ok)
        out["alerts"] = sum(len(v) for v in want.values())
        print(f"alerts equal in process: {sum(same.values())}/{len(same)}", flush=True)
    if "live" not in a.skip:
        out["live"] = live_phase(scenario, tmp / "live", link, a.insecure, sorted(peers) or None,
                                 want if "inproc" not in a.skip else None)


if __name__ == "__main__":
    raise SystemExit(main())
