"""The brigade across namespaced hosts (issue 32, done-when): one network namespace per
command post (`deploy init SCENARIO --addresses 198.18.0.0/24`: BDE, 1BN-3BN, CAV, FA,
SPT for the brigade), each running `saim-mesh deploy FILE --host H` under its own
supervisor, secure (mTLS, access control, certificates naming each host's address), a
`tc tbf` rate (default 64 kbit/s) on each host link below the top's (the BN-BDE links and
the brigade troops' links), the sources paced at `--speed` from one `start` in the file.
Three runs, each on fresh namespaces:

1. `free`: fault-free. `times_real_time`: event seconds over wall seconds from event time 0
   to the last EA peer done; `alerts_equal_in_process`: every EA peer's plan alerts
   (system problems apart) equal the in-process run's; `links`: bytes each way on every
   host link (the host's eth0 counters: Ethernet frames, so TLS, TCP and IP included);
2. `cut`: one BN host cut off (nftables drop on the bridge, silent) at `--cut-from` for
   `--cut-s` seconds of event time, healed; the figures of bench/results/partition.json,
   computed by bench/partition.py itself (`--analyze-only` over this run's alerts and the
   hosts' summaries merged as `mesh up` would have written them);
3. `host_kill`: one host killed (SIGKILL of everything in its namespace: supervisor,
   routers, EAs, sources) at `--kill-at`, started again `--down-s` event seconds later on
   the same folders; `lost_alert_s` (kill to the first system problem naming one of its
   sources, the worst over the EAs elsewhere depending on one), `alerts_equal_after_restart`,
   `duplicates`, from the same analysis.

Writes bench/results/hosts.json. Skips (exit 3, one line) where namespaces cannot be made.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import shutil
import signal
import sys
import subprocess
import time
import tomllib
from datetime import datetime, timezone
from pathlib import Path

from . import partition

from . import ROOT, results


def _iso(t: float) -> str:
    return datetime.fromtimestamp(t, timezone.utc).isoformat().replace("+00:00", "Z")


def _cli(args: list[str], what: str, timeout: float = 600) -> str:
    from saim_mesh.launch.proc import clean_env, py
    r = subprocess.run([*py(), *args], capture_output=True, text=True, env=clean_env(), timeout=timeout, cwd=ROOT)
    if r.returncode != 0:
        raise RuntimeError(f"{what}: exit {r.returncode}: {(r.stderr or r.stdout).strip()[-2000:]}")
    return r.stdout


def deployment(scenario: str, out: Path, pki: Path) -> dict:
    """`deploy init` (no consoles) + `certs --deploy`; the file's hosts as parsed."""
    out.parent.mkdir(parents=True, exist_ok=True)
    from saim_mesh.net import netns
    _cli(["deploy", "init", scenario, "--out", str(out), "--addresses", netns.SUBNET, "--no-consoles",
          "--pki", str(pki)], "deploy init")
    _cli(["certs", "--deploy", str(out)], "certs --deploy")
    return tomllib.loads(out.read_text())


def with_pace(base: Path, out: Path, speed: float, start: float, until: float | None, catch_up: str | None = None) -> None:
    """The base file with this run's pace: `speed`, one `start` for every host, `until`
    (and `catch_up` when asked)."""
    text = base.read_text()
    head = (f'speed = {speed:g}\nstart = "{_iso(start)}"\n' + (f"until = {until:g}\n" if until else "")
            + (f'catch_up = "{catch_up}"\n' if catch_up else ""))
    text, n = re.subn(r'^speed = "max".*$', head.rstrip("\n"), text, count=1, flags=re.M)
    if n != 1:
        raise RuntimeError(f"{base}: no `speed = \"max\"` line to replace")
    # paths in the file are relative to it: keep the new file beside the base
    out.write_text(text)


def iface_bytes(hs, host: str) -> dict:
    """The host's eth0 counters: tx = up (host -> bridge), rx = down."""
    from saim_mesh.net import netns
    d = json.loads(netns.sh(["ip", "-n", hs[host].netns, "-s", "-j", "link", "show", netns.IFACE], "link stats"))
    s = d[0]["stats64"]
    return {"up_bytes": s["tx"]["bytes"], "down_bytes": s["rx"]["bytes"], "up_packets": s["tx"]["packets"],
            "down_packets": s["rx"]["packets"], "up_dropped": s["tx"].get("dropped", 0)}


def restart_flag() -> list[str]:
    """What `deploy --host` needs to restart keeping its journals: nothing where it has
    `--fresh` (a restart on the same folder keeps this deployment's state by default);
    else `--resume`/`--restart`/`--keep` if it has one; else nothing (a fresh start)."""
    try:
        helptext = _cli(["deploy", "--help"], "deploy --help", 60)
    except RuntimeError:
        return []
    if re.search(r"(?<![\w-])--fresh(?![\w-])", helptext):
        return []
    for flag in ("--resume", "--restart", "--keep"):
        if re.search(rf"(?<![\w-]){re.escape(flag)}(?![\w-])", helptext):
            return [flag]
    return []


def kept_state(run_dir: Path, host: str) -> bool:
    """Whether the restarted host said it kept its state (its EAs' logs and journals)."""
    log = run_dir / "logs" / f"host-{host}-restarted.log"
    return log.exists() and f"host {host}: restart: keeping the state" in log.read_text(errors="replace")


def run_hosts(base: Path, hosts: dict, run_dir: Path, speed: float, until: float | None, rate: dict, lead: float,
              duration: float, *, cut: tuple[str, float, float] | None = None,
              kill: tuple[str, float, float] | None = None, grace: float = 180.0, log=print,
              catch_up: str | None = None, sysctls: dict | None = None) -> dict:
    """One run over fresh namespaced hosts (`sysctls` set in each host's stack); returns
    what was measured (and writes each host's summary.json under run_dir/hosts/<H>/)."""
    from saim_mesh.net import netns
    from saim_mesh.launch.proc import Proc, clean_env, py
    run_dir.mkdir(parents=True, exist_ok=True)
    hdir = run_dir / "hosts"
    shutil.rmtree(hdir, ignore_errors=True)
    procs: dict[str, Proc] = {}
    marks: dict = {}
    events: list[str] = []
    ready: dict[str, float] = {}
    done: dict[str, float] = {}
    errors: list[str] = []

    def say(m: str) -> None:
        events.append(f"{time.time():.2f} {m}")
        log(f"bench_hosts: {m}")

    with netns.Hosts(list(hosts), rate_kbit=rate, log=say, sysctls=sysctls or {}) as hs:
        for h, spec in hosts.items():
            if spec["addresses"][0] != hs.address(h):
                raise RuntimeError(f"host {h}: the file says {spec['addresses']}, the namespace has {hs.address(h)}")
        before = {h: iface_bytes(hs, h) for h in hosts}
        start = time.time() + lead
        f = base.parent / f"{base.stem}-{run_dir.name}.toml"
        with_pace(base, f, speed, start, until, catch_up)
        cmd = lambda h, extra=(): hs.wrap(h, [*py(), "deploy", str(f), "--host", h, "--out-dir",  # noqa: E731
                                              str(hdir / h), "--quiet", *extra])
        try:
            for h in hosts:
                procs[h] = Proc(f"host-{h}", cmd(h), env=clean_env(), log_dir=run_dir / "logs")
            for h, spec in hosts.items():
                if spec["eas"]:
                    procs[h].wait_for(f"host {h}: {len(spec['eas'])} EA peers ready", max(60.0, start + 600 - time.time()))
                ready[h] = round(time.time() - start, 2)
            say(f"every host's EA peers ready, {-max(ready.values()):.1f} s before event time 0")

            # what happens when: run by this (the main) thread: a process started from a thread
            # that then ends is sent SIGTERM by the kernel (proc.Proc sets PR_SET_PDEATHSIG, which
            # fires when the creating *thread* exits)
            plan: list[tuple[float, str]] = []
            if cut is not None:
                plan += [(cut[1], "cut"), (cut[1] + cut[2], "heal")]
            if kill is not None:
                plan += [(kill[1], "kill"), (kill[1] + kill[2], "restart")]
            plan.sort()

            def act(what: str) -> None:
                ev = lambda: (time.time() - start) * speed   # noqa: E731
                if what == "cut":
                    hs.cut(cut[0])
                    marks["cut_wall"] = time.time()
                    say(f"cut {cut[0]} at event time {ev():.1f}")
                elif what == "heal":
                    hs.heal(cut[0])
                    marks["heal_wall"] = time.time()
                    say(f"healed {cut[0]} at event time {ev():.1f}")
                elif what == "kill":
                    h = kill[0]
                    pids = hs.kill(h)
                    marks["kill_wall"] = time.time()
                    say(f"killed host {h} ({len(pids)} processes) at event time {ev():.1f}")
                elif what == "restart":
                    h = kill[0]
                    for u in hosts[h]["eas"]:   # what its commander was shown before the kill
                        p = hdir / h / f"{u}.jsonl"
                        if p.exists():
                            shutil.copy(p, hdir / h / f"{u}.jsonl.before-kill")
                    procs[h] = Proc(f"host-{h}-restarted", cmd(h, flag), env=clean_env(), log_dir=run_dir / "logs")
                    marks["restart_wall"] = time.time()
                    say(f"restarted host {h}{' ' + ' '.join(flag) if flag else ''} at event time {ev():.1f}")

            flag = restart_flag() if kill is not None else []
            marks["restart_flag"] = flag
            end = start + duration / speed + grace   # a host still not done by then is said, not waited for
            while len(done) < len(hosts) and time.time() < end:
                while plan and time.time() >= start + plan[0][0] / speed:
                    try:
                        act(plan.pop(0)[1])
                    except Exception as e:   # said in the result; the run goes on
                        errors.append(f"nemesis: {e}")
                        say(f"nemesis failed: {e}")
                for h, spec in hosts.items():
                    if h in done:
                        continue
                    n = len(spec["eas"])
                    if not n:
                        if not plan:
                            done[h] = time.time()
                        continue
                    if kill is not None and h == kill[0] and "restart_wall" not in marks:
                        continue   # its first life's line does not count
                    if procs[h].find(f"host {h}: {n} of {n} EA peers done") is not None:
                        done[h] = time.time()
                        say(f"host {h}: EA peers done at event time {(done[h] - start) * speed:.1f}")
                time.sleep(0.2)
            if len(done) < len(hosts):
                errors.append(f"not done {grace:g} s after the end: hosts {sorted(set(hosts) - set(done))} "
                              f"(stopped; their summaries are what they had)")
            after = {h: iface_bytes(hs, h) for h in hosts}
        finally:
            for p in procs.values():
                try:
                    p.stop(timeout=90)
                except Exception as e:
                    errors.append(f"stopping {p.name}: {e}")
        left = {h: hs.pids(h) for h in hosts}
    wall = max(done.values()) - start if done else None
    links = {}
    for h in hosts:
        if h == next(iter(hosts)):
            continue
        links[f"{h}-{next(iter(hosts))}"] = {
            "host": h, "rate_kbit": rate.get(h),
            **{k: after[h][k] - before[h][k] for k in after[h]},
        }
    for v in links.values():
        v["total_bytes"] = v["up_bytes"] + v["down_bytes"]
        if wall:
            v["kbit_s"] = round(v["total_bytes"] * 8 / 1000 / wall, 2)
            v["max_way_kbit_s"] = round(max(v["up_bytes"], v["down_bytes"]) * 8 / 1000 / wall, 2)
    return {"start": start, "wall_s": round(wall, 1) if wall else None, "event_s": duration,
            "times_real_time": round(duration / wall, 3) if wall else None, "ready_s_before_start": ready,
            "done": {h: round(t - start, 1) for h, t in done.items()}, "not_done": sorted(set(hosts) - set(done)), "links": links, "marks": marks,
            "events": events, "errors": errors, "left_processes": {h: p for h, p in left.items() if p}}


def merge(run_dir: Path, hosts: dict, start: float, killed: str | None = None, kept: bool = False) -> None:
    """The hosts' summaries and alert logs as one `mesh up` would have written them (what
    bench/partition.py reads): run_dir/summary.json and run_dir/<unit>.jsonl. A killed host
    restarted without keeping its logs: what its commander saw before the kill, then after."""
    peers, units, secure = {}, [], None
    for h, spec in hosts.items():
        d = run_dir / "hosts" / h
        try:
            s = json.loads((d / "summary.json").read_text())
        except FileNotFoundError:
            s = {"peers": {}}
        peers.update(s.get("peers", {}))
        secure = s.get("secure", secure)
        for u in spec["eas"]:
            units.append(u)
            dst = run_dir / f"{u}.jsonl"
            dst.unlink(missing_ok=True)
            parts = [d / f"{u}.jsonl"]
            if h == killed and not kept:
                parts.insert(0, d / f"{u}.jsonl.before-kill")
            with open(dst, "wb") as out:
                for p in parts:
                    if p.exists():
                        out.write(p.read_bytes())
    (run_dir / "summary.json").write_text(json.dumps({"peers": peers, "units": units, "paced_start": start,
                                                      "secure": secure}, default=str))


def in_process(scenario: str, units: list[str], until: float | None) -> dict[str, list]:
    """Every unit's alerts in process, sorted as bench/partition.py keys them (up to `until`)."""
    from saim_mesh import scenario as scenarios
    from saim_mesh.inprocess.runner import run
    sc = scenarios.load(scenario)
    if until is not None:   # the peers go on to the scenario's end on no more facts: so does this run
        sc.events = [e for e in sc.events if e.t <= until]
    return {ea.owner: sorted(partition._key(x.to_json_dict()) for x in ea.alerts) for ea in run(sc, units)}


def equal_in_process(run_dir: Path, units: list[str], want: dict[str, list]) -> dict:
    unequal = {}
    for u in units:
        got = sorted(map(partition._key, (x for x in partition._alerts(run_dir / f"{u}.jsonl") if partition._shown(x))))
        if got != want.get(u):
            g, w = set(got), set(want.get(u, []))
            unequal[u] = {"peer": len(got), "in_process": len(want.get(u, [])), "missing": len(w - g),
                          "extra": len(g - w)}
    return unequal


def analyze(base: Path, other: str, router: str, t0: float, secs: float, speed: float, frozen_s: float,
            scenario: str) -> dict:
    """bench/partition.py's own figures for `other` (a run folder beside `free`)."""
    out = base / f"partition-{other}.json"
    tmp = base / f"pair-{other}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    (tmp / "free").symlink_to((base / "free").resolve())
    (tmp / "cut").symlink_to((base / other).resolve())
    with contextlib.redirect_stdout(io.StringIO()):
        partition.main(["--scenario", scenario, "--speed", f"{speed:g}", "--cut", router, "--cut-from", f"{t0:g}",
                "--cut-s", f"{secs:g}", "--frozen-s", f"{frozen_s:g}", "--out-dir", str(tmp), "--analyze-only",
                "--out", str(out)])
    return json.loads(out.read_text())


def lost_after(run_dir: Path, hosts: dict, host: str, t_wall: float, own: bool = True) -> dict:
    """From `t_wall` (the cut or the kill) to the first system problem naming a lost source
    across it, per EA that depends on one (bench/partition.py takes the first such alert
    of the run, which is before the fault when a source was declared lost earlier, e.g.
    for a while at the start: those EAs are counted in `said_before`)."""
    summ = json.loads((run_dir / "summary.json").read_text())
    mine = set(hosts[host]["sources"])
    every = {s for h in hosts.values() for s in h["sources"]}
    out, before, never = {}, [], []
    for h, spec in hosts.items():
        if h == host and not own:   # a killed host's EAs are dead: they say nothing until restarted
            continue
        across = (every - mine) if h == host else mine
        for u in spec["eas"]:
            deps = set((summ["peers"].get(u) or {}).get("depends", [])) or across
            if not deps & across:
                continue
            gone = [x["details"]["declared_wall"] for x in partition._alerts(run_dir / f"{u}.jsonl")
                    if x["category"] == "system-problem" and x["details"].get("event") == "source-lost"
                    and x["subjects"][0] in across and "declared_wall" in x["details"]]
            if any(w < t_wall for w in gone):
                before.append(u)
            after = [w for w in gone if w >= t_wall]
            if after:
                out[u] = round(min(after) - t_wall, 2)
            else:
                never.append(u)
    return {"by_ea": out, "max": max(out.values(), default=None), "said_before": sorted(before),
            "never_said": sorted(never)}


CUT_KEYS = ("frozen_epochs_uncut", "on_time_share_uncut", "lost_alert_s_max", "alerts_equal_after_heal", "duplicates")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench_hosts", description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", help="default: brigade-small, generated on demand into out/scenarios")
    ap.add_argument("--speed", type=float, default=1.5, help="the sources' pace (x real time; at 3x the 64 kbit/s links carry three times real time's traffic)")
    ap.add_argument("--until", type=float, help="end the sources at this event time (default: the whole scenario)")
    ap.add_argument("--rate-kbit", type=int, default=64, help="tbf rate on each host link below the top's")
    ap.add_argument("--rate-hosts", help="comma-separated hosts whose link is rated (default: every host but the top's)")
    ap.add_argument("--runs", default="free,cut,kill", help="which runs (free is always run)")
    ap.add_argument("--catch-up", choices=["block", "yield"], help="the deployment's catch_up (default: the file's)")
    ap.add_argument("--notsent-lowat", type=int, metavar="BYTES",
                    help="net.ipv4.tcp_notsent_lowat in every host (unsent bytes a socket holds before Zenoh's "
                         "priority queues, not the kernel, order what goes next); default: the kernel's")
    ap.add_argument("--cut-host", help="default: the first host below the top's (1BN)")
    ap.add_argument("--cut-from", type=float, default=300.0)
    ap.add_argument("--cut-s", type=float, default=300.0)
    ap.add_argument("--kill-host", help="default: the second host below the top's (2BN)")
    ap.add_argument("--kill-at", type=float, default=450.0)
    ap.add_argument("--down-s", type=float, default=300.0, help="event seconds the killed host stays down")
    ap.add_argument("--frozen-s", type=float, default=4.0)
    ap.add_argument("--lead", type=float, default=None, help="wall seconds from starting the hosts to event time 0")
    ap.add_argument("--grace", type=float, default=180.0,
                    help="wall seconds a run waits for its hosts' EA peers after the scenario's end at pace")
    ap.add_argument("--keep-runs", default="", help="runs of --out-dir's runs.json to keep rather than run again "
                    "(e.g. free)")
    ap.add_argument("--out-dir", default="out/bench-hosts")
    ap.add_argument("--out", default="bench/results/hosts.json")
    ap.add_argument("--analyze-only", action="store_true", help="no runs: the figures from --out-dir's runs")
    ap.add_argument("--equal-from", metavar="JSON", help="with --analyze-only: the in-process comparison of an "
                    "earlier analysis of the same fault-free run (when the EA's code changed since the runs)")
    a = ap.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))   # stopped: the hosts' namespaces still go
    from saim_mesh import scenario as scenarios
    from saim_mesh.net import netns
    from saim_mesh.ondemand import ensure
    if why := netns.unavailable():
        print(f"bench_hosts: skipped: no namespaced hosts here: {why}")
        return 3
    netns.cleanup_stale()
    scenario = str(Path(a.scenario).resolve()) if a.scenario else str(ensure("brigade-small", ROOT / "out" / "scenarios"))
    sc = scenarios.load(scenario, events=False)
    duration = min(a.until, sc.duration_s) if a.until else sc.duration_s
    out_dir = Path(a.out_dir).resolve()
    t_all = time.monotonic()
    base = out_dir / "deploy.toml"
    keep = {x.strip() for x in a.keep_runs.split(",") if x.strip()}
    if a.analyze_only or keep:
        hosts = {h["name"]: h for h in tomllib.loads(base.read_text())["host"]}
    else:
        shutil.rmtree(out_dir, ignore_errors=True)
        out_dir.mkdir(parents=True)
        hosts = {h["name"]: h for h in deployment(scenario, base, out_dir / "pki")["host"]}
    names = list(hosts)
    top = names[0]
    rated = a.rate_hosts.split(",") if a.rate_hosts else names[1:]
    rate = {h: a.rate_kbit for h in rated} if a.rate_kbit else {}
    cut_host = a.cut_host or names[1]
    kill_host = a.kill_host or names[min(2, len(names) - 1)]
    n_eas = sum(len(h["eas"]) for h in hosts.values())
    lead = a.lead if a.lead is not None else 30.0 + 1.5 * max(len(h["eas"]) for h in hosts.values())
    runs = {x.strip() for x in a.runs.split(",") if x.strip()} | {"free"}
    print(f"bench_hosts: {Path(scenario).name}: {len(hosts)} hosts ({', '.join(names)}), {n_eas} EA peers, "
          f"{a.rate_kbit} kbit/s on {', '.join(rated)}; {duration:g} s at {a.speed:g}x; runs {sorted(runs)}", flush=True)
    sysctls = {"net.ipv4.tcp_notsent_lowat": a.notsent_lowat} if a.notsent_lowat else {}
    common = {"grace": a.grace, "catch_up": a.catch_up, "sysctls": sysctls}
    saved = out_dir / "runs.json"
    res = json.loads(saved.read_text()) if a.analyze_only or keep else {}
    res = {k: v for k, v in res.items() if a.analyze_only or k in keep}
    if not a.analyze_only:
        if "free" not in res:
            res["free"] = run_hosts(base, hosts, out_dir / "free", a.speed, a.until, rate, lead, duration,
                                    **common)
            saved.write_text(json.dumps(res, indent=1))
        if "cut" in runs and "cut" not in res:
            res["cut"] = run_hosts(base, hosts, out_dir / "cut", a.speed, a.until, rate, lead, duration,
                                   cut=(cut_host, a.cut_from, a.cut_s), **common)
            saved.write_text(json.dumps(res, indent=1))
        if "kill" in runs and "kill" not in res:
            res["kill"] = run_hosts(base, hosts, out_dir / "kill", a.speed, a.until, rate, lead, duration,
                                    kill=(kill_host, a.kill_at, a.down_s), **common)
            saved.write_text(json.dumps(res, indent=1))
    runs = set(res)
    merge(out_dir / "free", hosts, res["free"]["start"])
    if "cut" in res:
        merge(out_dir / "cut", hosts, res["cut"]["start"])
    if "kill" in res:
        kept = kept_state(out_dir / "kill", kill_host)
        res["kill"]["marks"]["kept_state"] = kept
        merge(out_dir / "kill", hosts, res["kill"]["start"], killed=kill_host, kept=kept)
    units = [u for h in hosts.values() for u in h["eas"]]
    t_ip = time.monotonic()
    if a.equal_from:
        prev = json.loads(Path(a.equal_from).read_text())
        want = {"_": [None] * prev["alerts_compared"]}
        unequal = prev["unequal"] if not prev["alerts_equal_in_process"] else {}
    else:
        want = in_process(scenario, units, a.until)
        unequal = equal_in_process(out_dir / "free", units, want)
    ip_s = time.monotonic() - t_ip
    free = res["free"]
    out: dict = {
        "scenario": Path(scenario).name, "hosts": names, "host_count": len(names), "ea_peers": n_eas,
        "sources": sorted(s for h in hosts.values() for s in h["sources"]),
        "secure": json.loads((out_dir / "free" / "summary.json").read_text()).get("secure"),
        "link_rate_kbps": a.rate_kbit or None, "catch_up": a.catch_up or "block",
        "tcp_notsent_lowat": a.notsent_lowat, "rated_links": [f"{h}-{top}" for h in rated],
        "speed": a.speed, "event_s": duration, "wall_s": free["wall_s"],
        "times_real_time": free["times_real_time"],
        "alerts_equal_in_process": not unequal and len(units) > 0, "unequal": unequal,
        "alerts_compared": sum(len(v) for v in want.values()), "peers_compared": len(units),
        "links": free["links"],
        "links_note": "bytes on each host's eth0 (Ethernet frames: TLS, TCP, IP included), fault-free run; "
                      "by key family not measured (the routers keep no per-key counters)",
        "hosts_not_done": free.get("not_done", []), "ready_s_before_start": free["ready_s_before_start"], "errors": {"free": free["errors"]},
        "left_processes": {"free": free["left_processes"]},
        "cut": None, "host_kill": None,
    }
    cut_router = f"r-{cut_host}"
    if "cut" in runs:
        r = res["cut"]
        out["errors"]["cut"], out["left_processes"]["cut"] = r["errors"], r["left_processes"]
        try:
            c0 = (r["marks"]["cut_wall"] - r["start"]) * a.speed if "cut_wall" in r["marks"] else a.cut_from
            p = analyze(out_dir, "cut", cut_router, c0, a.cut_s, a.speed, a.frozen_s, scenario)
        except BaseException as e:   # noqa: BLE001  (partition's argparse exits): said, the rest still written
            out["errors"]["cut"].append(f"analysis: {type(e).__name__}: {e}")
            p = {}
        la = lost_after(out_dir / "cut", hosts, cut_host, r["marks"]["cut_wall"]) if "cut_wall" in r["marks"] else {}
        out["cut"] = {"host": cut_host, "cut_from_t": a.cut_from, "cut_s": a.cut_s,
                      **{k: p.get(k) for k in CUT_KEYS},
                      "lost_alert_s_max": la.get("max"), "lost_alert_s_max_partition_py": p.get("lost_alert_s_max"),
                      "source_lost_said_before_cut": la.get("said_before"), "source_lost_never_said": la.get("never_said"),
                      **{k: p.get(k) for k in ("late", "unequal", "uncut_eas", "eas_depending_across",
                                               "uncut_epoch_lag_s", "inhibited_during_loss", "on_time_alerts_uncut")},
                      "marks_event_t": {k: round((v - r["start"]) * a.speed, 1) for k, v in r["marks"].items() if isinstance(v, float)},
                      "times_real_time": r["times_real_time"], "hosts_not_done": r.get("not_done", []),
                      "links": r["links"]}
    if "kill" in runs:
        r = res["kill"]
        out["errors"]["host_kill"], out["left_processes"]["host_kill"] = r["errors"], r["left_processes"]
        try:
            k0 = (r["marks"]["kill_wall"] - r["start"]) * a.speed if "kill_wall" in r["marks"] else a.kill_at
            p = analyze(out_dir, "kill", f"r-{kill_host}", k0, a.down_s, a.speed, a.frozen_s, scenario)
        except BaseException as e:   # noqa: BLE001
            out["errors"]["host_kill"].append(f"analysis: {type(e).__name__}: {e}")
            p = {}
        la = lost_after(out_dir / "kill", hosts, kill_host, r["marks"]["kill_wall"], own=False) if "kill_wall" in r["marks"] \
            else {}
        out["host_kill"] = {"host": kill_host, "kill_at_t": a.kill_at, "down_s": a.down_s,
                            "lost_alert_s": la.get("max"), "lost_alert_s_partition_py": p.get("lost_alert_s_max"),
                            "source_lost_said_before_kill": la.get("said_before"),
                            "source_lost_never_said": la.get("never_said"), "lost_alert_s_by_ea": la.get("by_ea"),
                            "alerts_equal_after_restart": p.get("alerts_equal_after_heal"),
                            "duplicates": p.get("duplicates"), "late": p.get("late"), "unequal": p.get("unequal"),
                            "restart_flag": " ".join(r["marks"].get("restart_flag") or []) or None,
                            "logs_kept_on_restart": bool(r["marks"].get("kept_state")),
                            "marks_event_t": {k: round((v - r["start"]) * a.speed, 1) for k, v in r["marks"].items()
                                      if isinstance(v, float)},
                            "times_real_time": r["times_real_time"], "hosts_not_done": r.get("not_done", [])}
    silence = None
    with contextlib.suppress(Exception):
        from saim_mesh.inprocess.runner import config_for
        sc_full = scenarios.load(scenario, events=False)
        silence = float(config_for(sc_full, sc_full.taskorg.root)["mesh"]["source_silence_s"])
    out["targets"] = {"times_real_time": 1.0, "alerts_equal_in_process": True, "hosts": 5,
                      "cut": {"frozen_epochs_uncut": 0, "on_time_share_uncut": 0.99,
                              "lost_alert_s_max": silence + 2 if silence else None,
                              "alerts_equal_after_heal": True, "duplicates": 0},
                      "host_kill": {"lost_alert_s": silence + 2 if silence else None,
                                    "alerts_equal_after_restart": True, "duplicates": 0}}
    c, k = out["cut"], out["host_kill"]
    met = {"free": bool((out["times_real_time"] or 0) >= 1.0 and out["alerts_equal_in_process"] and len(names) >= 5),
           "cut": bool(c and c["frozen_epochs_uncut"] == 0 and (c["on_time_share_uncut"] or 0) >= 0.99
                       and c["lost_alert_s_max"] is not None and silence and c["lost_alert_s_max"] <= silence + 2
                       and c["alerts_equal_after_heal"] and c["duplicates"] == 0),
           "host_kill": bool(k and k["lost_alert_s"] is not None and silence and k["lost_alert_s"] <= silence + 2
                             and k["alerts_equal_after_restart"] and k["duplicates"] == 0)}
    out["targets_met_by_part"] = met
    out["targets_met"] = all(met.values())
    out["in_process_s"] = round(ip_s, 1)
    if a.equal_from:
        out["in_process_compared"] = (f"by an earlier analysis of this fault-free run ({a.equal_from}), with the "
                                      "code the runs were made with")
    out["bench_wall_s"] = round(time.monotonic() - t_all, 1)
    results.write(a.out, out)
    print(json.dumps({k: v for k, v in out.items() if k not in ("links", "unequal")}, indent=1))
    return 0 if out["targets_met"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
