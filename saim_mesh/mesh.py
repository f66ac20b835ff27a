"""`saim-mesh mesh up`: one OS process per unit EA plus the replay, on loopback,
with alerts collected per peer and every child reaped on exit."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from .zconf import free_port


def mesh_units(sc) -> list[str]:
    """Battalion, companies and platoons: every unit above squad level."""
    return sorted(u for u, x in sc.taskorg.units.items() if x.echelon in ("battalion", "company", "platoon"))


class Proc:
    """A child process whose stdout lines we read (without blocking on them)."""

    def __init__(self, name: str, args: list[str], env=None):
        self.name = name
        self.p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        os.set_blocking(self.p.stdout.fileno(), False)
        self.lines: list[str] = []
        self._partial = ""

    def poll_lines(self) -> list[str]:
        try:
            chunk = self.p.stdout.read()
        except (TypeError, ValueError):
            chunk = None
        if not chunk:
            return []
        text = self._partial + chunk
        parts = text.split("\n")
        self._partial = parts.pop()
        self.lines += parts
        return parts

    def wait_for(self, prefix: str, timeout: float) -> str:
        end = time.monotonic() + timeout
        seen = 0
        while time.monotonic() < end:
            exited = self.p.poll() is not None   # checked first: then every line it wrote is readable
            self.poll_lines()
            for line in self.lines[seen:]:
                if line.startswith(prefix):
                    return line
            seen = len(self.lines)
            if exited:
                raise RuntimeError(f"{self.name} exited ({self.p.returncode}) before '{prefix}': "
                                   f"{self.p.stderr.read()[-2000:]}")
            time.sleep(0.01)
        raise TimeoutError(f"{self.name}: no '{prefix}' within {timeout} s")

    def stop(self) -> None:
        if self.p.poll() is None:
            self.p.terminate()
            try:
                self.p.wait(5)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait()


def py() -> list[str]:
    return [sys.executable, "-m", "saim_mesh"]


def start_replay(scenario: str, endpoint: str, root: str, wait: list[str], speed: str = "max",
                 linger: float = 30.0, window: float = 20.0) -> Proc:
    return Proc("replay", [*py(), "replay", scenario, "--listen", endpoint, "--root", root, "--speed", speed,
                           "--linger", str(linger), "--window", str(window), "--wait-peers", *wait])


def start_peer(scenario: str, unit: str, endpoint: str, root: str, out: str | Path, name: str | None = None,
               extra: list[str] = ()) -> Proc:
    return Proc(name or unit, [*py(), "peer", "--scenario", scenario, "--unit", unit, "--connect", endpoint,
                               "--listen", "tcp/127.0.0.1:0", "--root", root, "--out", str(out), *extra])


def start_fusion(scenario: str, group: str, endpoint: str, root: str, shuffle: int | None = None) -> Proc:
    return Proc(f"fusion-{group}", [*py(), "fusion", "--scenario", scenario, "--group", group, "--connect", endpoint,
                                    "--listen", "tcp/127.0.0.1:0", "--root", root]
                + (["--shuffle", str(shuffle)] if shuffle is not None else []))


def up(scenario: str, units: list[str] | None, out_dir: Path, speed: str = "max", timeout: float = 600.0,
       root: str | None = None, echo=print, window: float = 20.0) -> dict:
    from . import scenario as S
    sc = S.load(scenario, events=False)
    units = units or mesh_units(sc)
    groups = sorted(sc.meta.get("fusion", {}).get("groups", {}))
    out_dir.mkdir(parents=True, exist_ok=True)
    root = root or f"saim/{sc.name}/{os.getpid()}"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs: list[Proc] = []
    t0 = time.monotonic()
    try:
        replay = start_replay(scenario, endpoint, root, units + [f"fusion-{g}" for g in groups], speed,
                              window=window)
        procs.append(replay)
        replay.wait_for("ready", 60)
        fusion = [start_fusion(scenario, g, endpoint, root) for g in groups]
        procs += fusion
        for u in units:
            (out_dir / f"{u}.jsonl").unlink(missing_ok=True)
            procs.append(start_peer(scenario, u, endpoint, root, out_dir / f"{u}.jsonl"))
        summaries = {}
        end = time.monotonic() + timeout
        for p in procs[1 + len(fusion):]:
            line = p.wait_for("summary ", max(1.0, end - time.monotonic()))
            summaries[p.name] = json.loads(line[len("summary "):])
        replay.p.wait(max(1.0, end - time.monotonic()))
        replay.poll_lines()
        wall = time.monotonic() - t0
    finally:
        for p in procs:
            p.stop()
    echo(f"{'peer':>6} {'alerts':>7} {'flash':>6} {'facts':>7} {'subs':>5} {'rss MB':>7} {'wall s':>7}")
    for u, s in summaries.items():
        echo(f"{u:>6} {s['alerts']:>7} {s['by_priority'].get('flash', 0):>6} {s['facts']:>7} "
             f"{s['subscriptions']:>5} {s['peak_rss_mb']:>7} {s['wall_s']:>7}")
    echo(f"{len(summaries)} peers, wall {wall:.1f} s; alerts in {out_dir}/")
    return {"peers": summaries, "wall_s": wall, "replay": replay.lines}
