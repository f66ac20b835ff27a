"""Soak run of the live mesh (`mesh up`: a router, one source per command post, one secure
EA peer per unit advancing on its sources' watermarks), the recorded battle paced at
`--speed`, while:

- EA peers and sources are killed (SIGKILL) at random and restarted by the supervisor;
- one source is kept down past `[mesh] source_silence_s`: the EAs that depend on it
  declare it lost (a system-problem alert), then it comes back and they catch up, raising
  what fell due meanwhile marked late;
- a junk publisher (identity `ea.C`, valid certificate) puts random bytes and garbage on
  the keys it may use that the peers hear (`dir/C/confirm`, `bye/C`, ...);
- the radio link between company `--cut`'s router and the battalion's is cut for
  `--cut-s` wall seconds (SIGUSR1 to its emulated link, SIGUSR2 heals): the EAs on each side
  declare the sources across it lost, then catch up at the heal;
- a forged-directive publisher (identity `console.A2`, valid certificate) orders and
  confirms missions of units A2 does not command, and signs directives as someone else
  or for keys it may not sign: every peer must refuse and count them.

Writes bench/results/soak.json: what was sent, refused (counted by the peers), killed and
restarted; `alerts_lost` and `duplicates` (an alert id shown twice by one EA), both
target 0; `alerts_equal_fault_free` (each EA's plan alerts, system problems and those
inhibited by a source's loss apart, equal the fault-free in-process run's by time, type,
subjects, message, priority and id; late ones count as equal and are counted in
`late_alerts`); memory flat: `rss_second_half_growth_mb` (per process, over the second half
of its last run) at most `RSS_GROWTH_MB`.

The mesh runs with two routers (the battalion's and company `--cut`'s, linked through an
emulated link: `mesh up --topology FILE`); `--cut none` gives the one router of `mesh up`.
Not part of CI's default run: `scripts/soak`."""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import threading
import time
from collections import Counter
from pathlib import Path

import msgspec
import zenoh

from saim_mesh.authority import directives
from saim_mesh.protocol import wire
from saim_mesh.security import sign

from . import ROOT, RESULTS, results

BLOCK = zenoh.CongestionControl.BLOCK
RSS_GROWTH_MB = 24.0   # per process over the second half of its last run: "memory flat"
JUNK_ID, FORGER_ID = "ea.C", "console.A2"


# ------------------------------------------------------------------------------- judging
def plan_key(a: dict) -> tuple:
    """What an alert says, comparable across runs (tests/test_live.py `plan_alerts`)."""
    return (a["t"], a["type"], tuple(a["subjects"]), a["message"], a["priority"], a["details"].get("id"))


def shown(a: dict) -> bool:
    """A plan alert shown to the commander: not a system problem, not inhibited by a lost
    source (what an EA concludes about its units on a partial picture)."""
    return a["category"] != "system-problem" and "inhibited_by" not in a["details"]


def judge(want: dict[str, list[tuple]], got: dict[str, list[dict]]) -> dict:
    """Each EA's alerts as logged (`got`, dicts) against the fault-free run's (`want`,
    `plan_key` tuples): lost, extra, shown twice, late, inhibited, the unequal peers."""
    lost = extra = dups = 0
    late: dict[str, int] = {}
    inhibited = 0
    unequal = []
    for u, w in sorted(want.items()):
        logged = got.get(u, [])
        plan = [a for a in logged if shown(a)]
        inhibited += sum(1 for a in logged if a["category"] != "system-problem" and not shown(a))
        ids = Counter(a["details"].get("id") or plan_key(a) for a in plan)
        dups += sum(n - 1 for n in ids.values() if n > 1)
        if n_late := sum(1 for a in plan if a["details"].get("late")):
            late[u] = n_late
        g, wc = Counter(map(plan_key, plan)), Counter(w)
        have = Counter({k: 1 for k in g})   # a duplicate is counted once above, not as extra here
        lost += sum((wc - have).values())
        extra += sum((have - wc).values())
        if have != wc:
            unequal.append(u)
    return {"alerts_lost": lost, "alerts_extra": extra, "duplicates": dups, "late_alerts": late,
            "inhibited_during_loss": inhibited, "alerts_equal_fault_free": not unequal, "unequal_peers": unequal}


def lost_declared(got: dict[str, list[dict]], source: str) -> dict[str, float]:
    """EA -> wall time it declared `source` lost (its system-problem alert)."""
    out = {}
    for u, alerts in got.items():
        w = [a["details"].get("declared_wall", 0.0) for a in alerts if a["category"] == "system-problem"
             and a["details"].get("event") == "source-lost" and a["subjects"][:1] == [source]]
        if w:
            out[u] = min(w)
    return out


def growth_mb(samples: list[tuple[float, int, int]], half: float) -> float | None:
    """RSS growth over the second half of the run, of the process's last run (a restart
    starts small: its ramp-up is not a leak): mean of its last 5 samples minus its first 5."""
    last = samples[-1][1] if samples else None
    kb = [k for t, pid, k in samples if pid == last and t >= half and k > 0]
    if len(kb) < 10:
        return None
    return round((sum(kb[-5:]) - sum(kb[:5])) / 5 / 1024, 1)


def sum_kinds(dicts) -> dict:
    out: Counter = Counter()
    for d in dicts:
        out.update(d)
    return dict(sorted(out.items()))


# ------------------------------------------------------------------------------- faults
class Attackers(threading.Thread):
    """Junk as `ea.C` on the keys it may put that peers hear, and forged directives as
    `console.A2`, until stopped. `clock()`: the mesh's event time now."""

    def __init__(self, sc, pki: Path, root: str, endpoint: str, clock, router: str, rate_hz: float = 100.0):
        super().__init__(daemon=True)
        self.router = router
        self.sc, self.pki, self.root, self.ep, self.clock, self.rate = sc, pki, root, endpoint, clock, rate_hz
        self.stop_ev = threading.Event()
        self.sent = Counter()
        self.error: str | None = None
        to = sc.taskorg
        self.foreign = [m.id for m in sc.plan.missions if m.unit != "A2" and "A2" not in to.ancestors(m.unit)]

    def _session(self, name: str):
        from saim_mesh.launch.zenoh_config import config
        return zenoh.open(config([], [self.ep], pki=self.pki, name=name, sc=self.sc, root=self.root, mode="client",
                                routers=[self.router]))   # its relay

    def _forge(self, rnd: random.Random, signer: sign.Signer) -> tuple[str, str, bytes]:
        """(kind sent, key, payload): one forged directive of a random kind."""
        at = min(self.sc.duration_s - 1, max(0.0, self.clock()) + 10.0)
        mission = rnd.choice(self.foreign)
        k_order, k_confirm = directives.key(self.root, "A2", "order"), directives.key(self.root, "A2", "confirm")
        n = signer.next_n()
        kind = rnd.choice(("order_outside_command", "confirm_not_its_own", "signed_as_other", "signed_for_other_key",
                           "bad_signature"))
        if kind == "confirm_not_its_own":
            body = msgspec.msgpack.encode(directives.make("confirm", req=directives._req(), n=n, at=at, mission=mission,
                                                          phase="start"))
            return kind, k_confirm, signer.sign(k_confirm, body, n)
        action = rnd.choice(("start-mission", "end-mission"))
        body = msgspec.msgpack.encode(directives.make("order", req=directives._req(), n=n, at=at, action=action,
                                                      mission=mission))
        if kind == "order_outside_command":
            return kind, k_order, signer.sign(k_order, body, n)
        if kind == "signed_for_other_key":   # its own signature over the battalion's key, put on its own
            return kind, k_order, signer.sign(directives.key(self.root, "BN", "order"), body, n)
        by = "console.BN" if kind == "signed_as_other" else signer.name
        env = sign.Signed(v=sign.VERSION, by=by, n=n, key=k_order, body=body, sig=bytes(rnd.randbytes(64)))
        return kind, k_order, sign._ENC.encode(msgspec.msgpack.Ext(sign.EXT, sign._ENC.encode(env)))

    def run(self) -> None:
        try:
            rnd = random.Random(1)
            signer = sign.load_signer(self.pki, FORGER_ID)
            ahead = wire.encode(wire.make(wire.Ack, t=1e8))   # well-formed, dated past any scenario's end
            with self._session(JUNK_ID) as junk, self._session(FORGER_ID) as forge:
                while not self.stop_ev.wait(1.0 / self.rate):
                    k = rnd.choice(("dir/C/confirm", "bye/C", "ack/C/cp.BN", "alert/C/contact", "health/C"))
                    payload = rnd.choice((rnd.randbytes(rnd.randint(1, 64)), b"\xc1", ahead, b"\x00" * 100_000,
                                          rnd.randbytes(2000)))
                    junk.put(f"{self.root}/{k}", payload)
                    self.sent["junk"] += 1
                    if self.sent["junk"] % 50 == 0:
                        kind, key, payload = self._forge(rnd, signer)
                        forge.put(key, payload, congestion_control=BLOCK)
                        self.sent[f"forged_{kind}"] += 1
                        self.sent["forged_directives"] += 1
        except Exception as e:   # the soak reports it; the mesh run goes on
            self.error = f"{type(e).__name__}: {e}"


class Chaos(threading.Thread):
    """Kill a random EA or source (SIGKILL) every `every_s` wall seconds on average; at
    event time `hold_at` kill `hold` and keep it down for `hold_s` wall seconds (out of
    the supervisor's hands), then let the supervisor restart it. Stops killing at 85% of
    the battle, so the last restarts have time to catch up."""

    def __init__(self, sup, victims: list[str], kills: int, every_s: float, rnd: random.Random, clock,
                 end_t: float, hold: str, hold_at: float, hold_s: float):
        super().__init__(daemon=True)
        self.sup, self.victims, self.kills, self.every, self.rnd, self.clock = sup, victims, kills, every_s, rnd, clock
        self.end_t, self.hold, self.hold_at, self.hold_s = end_t, hold, hold_at, hold_s
        self.killed: list[dict] = []
        self.held: dict = {}
        self.stop_ev = threading.Event()

    def _kill(self, name: str) -> int | None:
        try:
            pid = self.sup.procs[name].p.pid
            os.kill(pid, signal.SIGKILL)
            return pid
        except (KeyError, ProcessLookupError, OSError):
            return None

    def run(self) -> None:
        held_done = False
        while not self.stop_ev.wait(self.every * (0.5 + self.rnd.random())):
            if self.clock() > 0.85 * self.end_t:
                break
            if not held_done and self.clock() >= self.hold_at:
                held_done = True
                self.sup.given_up.add(self.hold)   # down for good, as far as the supervisor knows
                pid = self._kill(self.hold)
                self.held = {"process": self.hold, "pid": pid, "down_wall": time.time(), "event_t": round(self.clock())}
                print(f"soak: {self.hold} down for {self.hold_s:g} s", flush=True)
                if self.stop_ev.wait(self.hold_s):
                    break
                self.sup.given_up.discard(self.hold)   # the supervisor restarts it
                self.held["up_wall"] = time.time()
                print(f"soak: {self.hold} let back", flush=True)
                continue
            if len(self.killed) >= self.kills:
                continue
            name = self.rnd.choice([v for v in self.victims if v != self.hold or held_done])
            if (pid := self._kill(name)) is not None:
                self.killed.append({"process": name, "pid": pid, "event_t": round(self.clock())})
                print(f"soak: killed {name}", flush=True)


class Cut(threading.Thread):
    """Cut the emulated link `name` at event time `at_t` for `for_s` wall seconds, then heal it."""

    def __init__(self, sup, name: str, clock, at_t: float, for_s: float):
        super().__init__(daemon=True)
        self.sup, self.name, self.clock, self.at_t, self.for_s = sup, name, clock, at_t, for_s
        self.stop_ev = threading.Event()
        self.done: dict = {}

    def run(self) -> None:
        while self.clock() < self.at_t:
            if self.stop_ev.wait(0.2):
                return
        pid = self.sup.procs[self.name].p.pid
        os.kill(pid, signal.SIGUSR1)
        self.done = {"link": self.name, "event_t": round(self.clock()), "cut_s": self.for_s, "healed": False}
        print(f"soak: cut {self.name}", flush=True)
        self.stop_ev.wait(self.for_s)
        os.kill(pid, signal.SIGUSR2)
        self.done["healed"] = True
        print(f"soak: healed {self.name}", flush=True)


class Sampler(threading.Thread):
    """Every process's RSS once a second: (wall, pid, kB) per name."""

    def __init__(self, sup):
        super().__init__(daemon=True)
        self.sup, self.samples = sup, {}
        self.stop_ev = threading.Event()

    def run(self) -> None:
        while not self.stop_ev.wait(1.0):
            for name, p in list(self.sup.procs.items()):
                self.samples.setdefault(name, []).append((time.time(), p.p.pid, _rss_kb(p.p.pid)))


def _rss_kb(pid: int) -> int:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def _endpoint(sup, router: str) -> str:
    args = sup.procs[router].args
    return args[args.index("--listen") + 1]


# ------------------------------------------------------------------------------- the run
def soak(scenario: str, out_dir: Path, speed: float, kills: int, every_s: float, hold: str, hold_at: float,
         hold_s: float | None, seed: int = 11, restarts: int = 10, timeout: float | None = None,
         cut: str | None = None, cut_at: float = 3000.0, cut_s: float = 30.0) -> dict:
    """One soak of the live mesh; returns the result written to soak.json."""
    from saim_mesh import scenario as scenarios
    from saim_mesh.live.up import cp_sources, up
    from saim_mesh.inprocess.runner import config_for, run as run_in_process
    from saim_mesh.scenario import mesh_units
    sc = scenarios.load(scenario, events=False)
    units = mesh_units(sc)
    sources = list(cp_sources(sc))
    silence = float(config_for(sc, sc.taskorg.root)["mesh"]["source_silence_s"])
    hold_s = hold_s if hold_s is not None else silence + 15.0
    if hold not in sources:
        raise ValueError(f"hold {hold}: not one of the sources {', '.join(sources)}")
    t_wall0 = time.monotonic()
    parts: dict = {}
    top = sc.taskorg.root
    hub, topology, link = "hub", None, None
    if cut is not None:   # the battalion's router and company `cut`'s, linked through an emulated link
        if sc.taskorg.parent.get(cut) != top:
            raise ValueError(f"cut {cut}: not a unit directly under {top}")
        out_dir.mkdir(parents=True, exist_ok=True)
        topology = out_dir / "soak-topology.toml"
        topology.write_text(f'[[router]]\nname = "r-{top}"\ncp = "{top}"\n\n'
                            f'[[router]]\nname = "r-{cut}"\ncp = "{cut}"\nlinks = ["r-{top}"]\n')
        hub, link = f"r-{top}", {"delay_ms": 0.0}

    def on_started(sup, t0) -> None:
        clock = lambda: (time.time() - t0) * speed   # noqa: E731  the sources' shared event time
        parts["attackers"] = Attackers(sc, out_dir / "pki", f"saim/{sc.name}/live", _endpoint(sup, hub), clock, hub)
        parts["chaos"] = Chaos(sup, [*units, *sources], kills, every_s, random.Random(seed), clock, sc.duration_s,
                               hold, hold_at, hold_s)
        parts["sampler"] = Sampler(sup)
        if cut is not None:
            parts["cut"] = Cut(sup, f"link-r-{cut}-r-{top}", clock, cut_at, cut_s)
        for th in parts.values():
            th.start()

    try:
        res = up(scenario, None, out_dir, speed=f"{speed:g}", show=False, on_started=on_started,
                 timeout=timeout or sc.duration_s / speed + 600, max_restarts=restarts,
                 topology=str(topology) if topology else None, link=link)
    finally:
        for th in parts.values():
            th.stop_ev.set()
        for th in parts.values():
            th.join(10)
    wall_end = time.time()
    att, chaos, sampler = parts["attackers"], parts["chaos"], parts["sampler"]
    print("soak: the fault-free run in process ...", flush=True)
    want = {ea.owner: [plan_key(x.to_json_dict()) for x in ea.alerts]
            for ea in run_in_process(scenarios.load(scenario), units)}
    got = {u: _alerts(out_dir / f"{u}.jsonl") for u in units}
    verdict = judge(want, got)
    peers = res["peers"]
    declared = lost_declared(got, hold)
    down = chaos.held.get("down_wall")
    t_start = min((s[0][0] for s in sampler.samples.values() if s), default=wall_end)
    half = t_start + (wall_end - t_start) / 2
    grow = {n: g for n, s in sorted(sampler.samples.items()) if (g := growth_mb(s, half)) is not None}
    depends_on_hold = sorted(u for u, p in peers.items() if hold in p.get("depends", []))
    out = {
        "mesh": "live", "scenario": Path(scenario).name, "speed": speed, "peers": len(units), "sources": sources,
        # 0: every EA peer said its summary and nothing was given up (up() runs in this process)
        "mesh_exit_code": 0 if len(peers) == len(units) and not res["given_up"] else 1, "secure": res["secure"],
        "wall_s": round(time.monotonic() - t_wall0, 1),
        "messages_sent": dict(sorted(att.sent.items())), "attacker_error": att.error,
        "rejects_counted_by_peers": sum(sum(p.get("rejects", {}).values()) for p in peers.values()),
        "rejects_by_kind": sum_kinds(p.get("rejects", {}) for p in peers.values()),
        "peers_counting_directive_rejects": sum(1 for p in peers.values()
                                                if any(k in p.get("rejects", {}) for k in ("directive", "signed"))),
        "killed": chaos.killed, "crashes_seen": sum(1 for e in res["events"] if "exit_code" in e),
        "restarts": sum(1 for e in res["events"] if "restarted" in e), "given_up": res["given_up"],
        "held_down": {**{k: v for k, v in chaos.held.items() if k in ("process", "event_t")}, "down_s": hold_s,
                      "source_silence_s": silence, "eas_depending": depends_on_hold,
                      "eas_declaring_lost": sorted(declared),
                      "declared_after_s_max": round(max(declared.values()) - down, 2) if declared and down else None},
        "cut": parts["cut"].done if cut is not None else None,
        "rebuilds": sum(p.get("rebuilds", 0) for p in peers.values()),
        **verdict,
        "peak_rss_mb": {n: round(max(k for *_, k in s) / 1024, 1) for n, s in sorted(sampler.samples.items()) if s},
        "rss_second_half_growth_mb": grow, "rss_growth_limit_mb": RSS_GROWTH_MB,
        "memory_flat": all(g <= RSS_GROWTH_MB for g in grow.values()),
        "targets": {"alerts_lost": 0, "duplicates": 0, "alerts_equal_fault_free": True, "memory_flat": True},
    }
    out["targets_met"] = (out["alerts_lost"] == 0 and out["duplicates"] == 0 and out["alerts_equal_fault_free"]
                          and out["memory_flat"] and out["mesh_exit_code"] == 0)
    return out


def _alerts(path: Path) -> list[dict]:
    try:
        return [json.loads(x) for x in open(path, encoding="utf-8") if x.endswith("\n")]
    except FileNotFoundError:
        return []


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="soak", description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion"))
    ap.add_argument("--speed", type=float, default=15.0, help="the battle's pace: x real time")
    ap.add_argument("--kills", type=int, default=10)
    ap.add_argument("--every", type=float, default=12.0, help="mean wall seconds between kills")
    ap.add_argument("--hold", default="cp.C", help="the source kept down past its silence limit")
    ap.add_argument("--hold-at", type=float, default=1800.0, help="event second it goes down")
    ap.add_argument("--hold-s", type=float, help="wall seconds it stays down (default: source_silence_s + 15)")
    ap.add_argument("--cut", default="C", help="the company whose router's link is cut (none: one router)")
    ap.add_argument("--cut-at", type=float, default=3000.0, help="event second the link is cut")
    ap.add_argument("--cut-s", type=float, default=30.0, help="wall seconds it stays cut")
    ap.add_argument("--out-dir", default=str(ROOT / "out" / "soak"))
    ap.add_argument("--result", default=str(RESULTS / "soak.json"))
    ap.add_argument("--seed", type=int, default=11)
    a = ap.parse_args(argv)
    res = soak(a.scenario, Path(a.out_dir), a.speed, a.kills, a.every, a.hold, a.hold_at, a.hold_s, a.seed,
               cut=None if a.cut == "none" else a.cut, cut_at=a.cut_at, cut_s=a.cut_s)
    results.write(a.result, res)
    print(json.dumps({k: v for k, v in res.items() if k not in ("killed", "peak_rss_mb")}, indent=1))
    return 0 if res["targets_met"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
