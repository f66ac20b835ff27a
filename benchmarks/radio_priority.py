"""Do Zenoh's priorities keep live frames on time over a radio link that a catch-up
fills? Two namespaced hosts, a router each, one 64 kbit/s `tbf` link between them (as in
`bench_hosts`); on the far host a live publisher (BLOCK, default priority, 200 B every
100 ms) and, in the second and third phases, a bulk publisher as a yielding journal sends
(DROP, DATA_LOW, 8 kB every 20 ms); the subscriber beyond the link times each live message.
Phases: live alone; behind the bulk; behind the bulk with the routers' kernel send buffer
bounded (SO_SNDBUF 8 kB), with Zenoh batches of 2 kB (and 4 kB send buffers); behind a
bulk paced below the link's rate (24 and 48 kbit/s offered: what `srcjournal.Pacer` does).
Writes bench/results/radio_priority.json (needs root)."""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import sys
import time
from pathlib import Path

from saim_mesh.launch.proc import wait_line
from .stats import percentiles

from . import RESULTS, ROOT

OUT = RESULTS / "radio_priority.json"
# phase: (the bulk's kbit/s offered: None none, 3200 as fast as it can go; the routers' SO_SNDBUF;
# their Zenoh batch_size): None as deployed
PHASES = {"alone": (None, None, None), "behind_bulk": (3200, None, None),
          "behind_bulk_sndbuf_8k": (3200, "8192", None), "behind_bulk_batch_2k": (3200, None, "2048"),
          "behind_bulk_batch_2k_sndbuf_4k": (3200, "4096", "2048"),
          "behind_bulk_paced_24k": (24, None, None), "behind_bulk_paced_48k": (48, None, None)}


def phase(out: Path, bulk: float | None, sndbuf: str | None, batch: str | None, rate: int, secs: float) -> dict:
    from saim_mesh.net.netns import Hosts
    shutil.rmtree(out, ignore_errors=True)   # the logs are appended to
    out.mkdir(parents=True)
    env = {**os.environ, **({"RADIO_SNDBUF": sndbuf} if sndbuf else {}), **({"RADIO_BATCH": batch} if batch else {}),
           **({"RADIO_BULK_EVERY": f"{8000 * 8 / 1000 / bulk:g}"} if bulk else {})}
    with Hosts(2) as hs:
        e0, e1 = (f"tcp/{hs.address(h)}:7447" for h in ("h0", "h1"))

        def run(host: str, args: list[str], name: str) -> Path:
            log = out / f"{name}.log"
            p = hs.run(host, [sys.executable, "-m", "benchmarks.radio_node", *args], log=log,
                       cwd=ROOT, env=env)
            wait_line(log, p, "ready", 60)
            return log
        run("h0", ["router", e0], "r0")
        run("h1", ["router", e1, e0], "r1")
        hs.set_rate("h1", rate)
        sub = run("h0", ["sub", e0, "radio/**"], "sub")
        run("h1", ["live", e1, "radio/live"], "live")
        if bulk is not None:
            run("h1", ["bulk", e1, "radio/bulk"], "bulk")
        time.sleep(secs)   # the measurement's length, not a synchronisation
    text = sub.read_text()
    lat = [float(x) for x in re.findall(r"^lat ([\d.]+)$", text, re.M)]
    bulk_bytes = sum(int(x) for x in re.findall(r"^bulk (\d+)$", text, re.M))
    return {"live_latency_s": percentiles(lat, 3), "live_sent_per_s": 10,
            "live_received": len(lat), "bulk_kbit_s": round(bulk_bytes * 8 / 1000 / secs, 1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench_radio_priority", description=__doc__)
    ap.add_argument("--rate-kbit", type=int, default=64)
    ap.add_argument("--secs", type=float, default=60.0, help="wall seconds per phase")
    ap.add_argument("--out-dir", default="out/bench-radio-priority")
    ap.add_argument("--out", default=str(OUT))
    a = ap.parse_args(argv)
    from saim_mesh.net import netns
    if why := netns.unavailable():
        print(f"bench_radio_priority: skipped: no namespaced hosts here: {why}")
        return 3
    netns.cleanup_stale()
    res = {"rate_kbit": a.rate_kbit, "secs_per_phase": a.secs, "phases": {}}
    for name, (bulk, sndbuf, batch) in PHASES.items():
        res["phases"][name] = phase(Path(a.out_dir) / name, bulk, sndbuf, batch, a.rate_kbit, a.secs)
        print(name, json.dumps(res["phases"][name]), flush=True)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
