"""How the commander's console holds up under the battalion at full speed (issue #9, 6).

One run of `mesh up --console` (secure, every battalion EA peer, the replay at max speed)
with headless Chromium on the page from before the first alert to the end. Measured,
written to bench/results/console.json:
- alerts pushed per second: the alerts the page drew, over the wall time from its first
  to its last (and the mesh's total for comparison);
- raise-to-render latency: from the replay's tick at which an alert fell due (its wall
  stamp) to the page drawing it (`window.__latencies()`), p50/p99/max. Baseline from the
  same run: the EA peers' own tick-to-alert latency (their summaries), so the console's
  share is the difference;
- responsiveness while it runs: wall time of a trivial script round trip into the page,
  sampled every 0.25 s (p50/p99/max), and the page's long tasks (PerformanceObserver);
- page memory after the whole battalion: JS heap and DOM nodes (Chrome DevTools metrics).
`--screenshot PNG` also saves the page at the end (the README's picture).
"""
from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

from .proc import Proc, clean_env, py
from . import results

ROOT = Path(__file__).resolve().parents[1]
LONGTASKS = """window.__longTasks = [];
try { new PerformanceObserver((l) => { for (const e of l.getEntries()) window.__longTasks.push(e.duration); })
      .observe({ type: "longtask", buffered: true }); } catch (e) {}"""


def _pcts(xs: list[float]) -> dict:
    if not xs:
        return {"n": 0}
    ys = sorted(xs)
    pick = lambda q: round(ys[min(len(ys) - 1, int(q * len(ys)))], 1)   # noqa: E731
    return {"n": len(ys), "p50": pick(0.50), "p99": pick(0.99), "max": round(ys[-1], 1)}


def run(scenario: Path, out_dir: Path, speed: str = "max", screenshot: Path | None = None,
        timeout_s: float = 1200.0) -> dict:
    from selenium.webdriver.common.by import By  # noqa: F401  (selenium is a test extra)
    from tests.browser import chromium
    t_start = time.monotonic()
    proc = Proc("mesh-up", [*py(), "mesh", "up", str(scenario), "--speed", speed, "--out-dir", str(out_dir),
                            "--console", "0", "--console-linger", "600"], env=clean_env(), log_dir=out_dir)
    try:
        url = proc.wait_for("http://127.0.0.1:", 180).split()[0]
        with chromium() as d:
            d.set_window_size(1600, 1000)
            d.get(url)
            d.execute_script(LONGTASKS)
            opened_ms = d.execute_script("return Date.now()")
            rtt: list[float] = []
            end = time.monotonic() + timeout_s
            def peers_done() -> bool:   # every EA peer said its summary (the run is over)
                logs = [p for p in (out_dir / "logs").glob("*.log")
                        if p.stem not in ("replay", "console", "tak") and not p.stem.startswith("fusion")]
                return bool(logs) and all("summary " in p.read_text(errors="replace") for p in logs)
            while time.monotonic() < end:
                t0 = time.perf_counter()
                d.execute_script("return document.querySelectorAll('li.alert').length")
                rtt.append(1000 * (time.perf_counter() - t0))
                if proc.p.poll() is not None:
                    raise RuntimeError(f"mesh up exited early: {proc.tail()}")
                if peers_done():
                    break
                time.sleep(0.25)   # a sampling period, not a synchronisation
            lat = d.execute_script("return window.__latencies()")
            live = [e for e in lat if e["due_ms"] is not None and e["due_ms"] >= opened_ms]
            drawn = [e["rendered_ms"] for e in lat]
            d.execute_cdp_cmd("Performance.enable", {})
            metrics = {m["name"]: m["value"] for m in d.execute_cdp_cmd("Performance.getMetrics", {})["metrics"]}
            long_tasks = d.execute_script("return window.__longTasks || []")
            seen = d.execute_script("return window.__alertsSeen")
            if screenshot is not None:
                screenshot.parent.mkdir(parents=True, exist_ok=True)
                d.save_screenshot(str(screenshot))
    finally:
        proc.stop()
    peers = {}
    for p in sorted(out_dir.glob("logs/*.log")):
        for line in p.read_text(errors="replace").splitlines():
            if line.startswith("summary "):
                s = json.loads(line[len("summary "):])
                if isinstance(s, dict) and "alerts" in s:   # an EA peer's (not another process's)
                    peers[p.stem] = s
    mesh_alerts = sum(s["alerts"] for s in peers.values())
    peer_p99 = max((s.get("alert_latency_ms", {}).get("p99", 0.0) for s in peers.values()), default=None)
    span_s = (max(drawn) - min(drawn)) / 1000 if len(drawn) > 1 else 0.0
    return {
        "scenario": scenario.name, "speed": speed, "peers": len(peers),
        "wall_s": round(time.monotonic() - t_start, 1),
        "alerts_mesh": mesh_alerts, "alerts_page": seen, "alerts_live": len(live),
        "alerts_per_s_pushed": round(seen / span_s, 1) if span_s else None,
        "render_latency_ms": _pcts([e["latency_ms"] for e in live]),
        "baseline_peer_alert_latency_p99_ms": peer_p99,
        "page_rtt_ms": _pcts(rtt),
        "long_tasks": {"n": len(long_tasks), "max_ms": round(max(long_tasks), 1) if long_tasks else 0.0,
                       "total_ms": round(sum(long_tasks), 1)},
        "page_memory": {"js_heap_used_mb": round(metrics.get("JSHeapUsedSize", 0) / 2**20, 1),
                        "js_heap_total_mb": round(metrics.get("JSHeapTotalSize", 0) / 2**20, 1),
                        "dom_nodes": int(metrics.get("Nodes", 0))},
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion"))
    ap.add_argument("--speed", default="max")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "console.json"))
    ap.add_argument("--screenshot", default=None, metavar="PNG")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-console-") as tmp:
        res = run(Path(a.scenario), Path(tmp), a.speed, Path(a.screenshot) if a.screenshot else None)
    res["machine"] = {"python": platform.python_version(), "cpu": platform.processor() or platform.machine()}
    results.write(a.out, res, echo=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
