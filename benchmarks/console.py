"""A commander who watches is never flooded (issues #9 and #30): the console under the
battalion at full speed, nobody acknowledging.

One run of `mesh up --console` (secure, every EA peer armed, the sources at max speed) with
headless Chromium on the page from before the first alert to the end, and the same run
without a console (peers unarmed), measured by the same invocation (`--baseline mesh`, the
default; `--baseline inprocess` takes the unarmed in-process run of the same units
instead, which raises the same plan alerts without the peers' wall-clock presence notes).
Written to bench/results/console.json:
- `alerts_mesh`, `flash_mesh`: lines (and flash lines) in the peers' alert logs
  (`<unit>.jsonl`) of the run with the console; `alerts_unarmed`, `flash_unarmed`: the
  same without it. Re-notifications and escalations are not alerts: watching must not
  multiply the alerts (target: at most 1.25 x unarmed, both);
- `notifications`: re-notification lines (kind renotify) in the peers' notice logs
  (`<unit>.notify.jsonl`); `escalations`: escalations, each counted once, in its sender's
  log (an escalation is logged by the EA that sent it and by the superior's that got it);
- `render_latency_ms` {n, p50, p95, p99, max}: from the page receiving an alert (its
  server-sent event) to its story's row drawn (`window.__latencies()`, render_ms; target
  p99 <= 100 ms); `raise_to_render_ms`: from the clock step (a source's watermark) at which the
  alert fell due to its row drawn (it includes the EA peer's own time to the alert,
  `baseline_peer_alert_latency_p99_ms`, and the server's 100 ms batching);
- `first_paint_ms`: a page opened on the console at the end of the run (the whole run in
  its snapshot): from navigation start to the snapshot drawn (`window.__firstPaintMs`;
  target <= 1000 ms); `first_paint_open_ms` the page opened at the start;
- the page while it runs: responsiveness (a trivial script's round trip every 0.25 s),
  long tasks, frames (`window.__frames`), memory; what it showed (stories, notices).
`targets` says which targets were met; the exit code is 0 either way (the figures are the
result). `--screenshot PNG` also saves the page at the end (the README's picture).
"""
from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

from saim_mesh.launch.proc import Proc, clean_env, py
from . import results
from .stats import percentiles

from . import ROOT

LONGTASKS = """window.__longTasks = [];
try { new PerformanceObserver((l) => { for (const e of l.getEntries()) window.__longTasks.push(e.duration); })
      .observe({ type: "longtask", buffered: true }); } catch (e) {}"""
TARGETS = {"alerts_ratio": 1.25, "flash_ratio": 1.25, "render_p99_ms": 100.0, "first_paint_ms": 1000.0}


def _pcts(xs: list[float]) -> dict:
    return percentiles(xs, 1)


def _jsonl(path: Path) -> list[dict]:
    out = []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            d = json.loads(line)
        except ValueError:
            continue   # a half-written last line (a killed peer)
        if isinstance(d, dict):
            out.append(d)
    return out


def alert_logs(out_dir: Path) -> dict[str, list[dict]]:
    """Each peer's alert log (`<unit>.jsonl`, not its notice log)."""
    return {p.name.removesuffix(".jsonl"): _jsonl(p) for p in sorted(out_dir.glob("*.jsonl"))
            if not p.name.endswith(".notify.jsonl")}


def notice_counts(out_dir: Path) -> dict:
    """Re-notifications, and escalations once each (the sender's line: its owner is the
    log's unit; the superior's log has the same notice with the subordinate as owner)."""
    renotify = escalate = received = 0
    for p in sorted(out_dir.glob("*.notify.jsonl")):
        unit = p.name.removesuffix(".notify.jsonl")
        for n in _jsonl(p):
            if n.get("kind") == "renotify":
                renotify += 1
            elif n.get("kind") == "escalate":
                if n.get("owner") == unit:
                    escalate += 1
                else:
                    received += 1
    return {"notifications": renotify, "escalations": escalate, "escalations_received": received}


def _counts(logs: dict[str, list[dict]]) -> tuple[int, int]:
    alerts = sum(len(v) for v in logs.values())
    flash = sum(1 for v in logs.values() for a in v if a.get("priority") == "flash")
    return alerts, flash


def _peers_done(out_dir: Path, units: list[str]) -> bool:
    """Every EA peer `mesh up` started (the scenario's mesh units, by name: the other
    processes' logs, `console-BN`, `cp.A`, `hub`, ..., never say a summary) said its
    summary: the run is over."""
    logs = [out_dir / "logs" / f"{u}.log" for u in units]
    return bool(logs) and all(p.exists() and "summary " in p.read_text(errors="replace") for p in logs)


def _summaries(out_dir: Path) -> dict[str, dict]:
    peers = {}
    for p in sorted(out_dir.glob("logs/*.log")):
        for line in p.read_text(errors="replace").splitlines():
            if line.startswith("summary "):
                try:
                    s = json.loads(line[len("summary "):])
                except ValueError:
                    continue
                if isinstance(s, dict) and "alerts" in s:   # an EA peer's (not another process's)
                    peers[p.stem] = s
    return peers


def _mesh_up(scenario: Path, out_dir: Path, speed: str, console: bool) -> Proc:
    extra = ["--console", "0", "--console-linger", "600"] if console else []
    return Proc("mesh-up", [*py(), "mesh", "up", str(scenario), "--speed", speed, "--out-dir", str(out_dir), *extra],
                env=clean_env(), log_dir=out_dir)


def _mesh_units(scenario: Path) -> list[str]:
    """The EA peers `mesh up` starts for this scenario."""
    from saim_mesh import scenario as scenarios
    return scenarios.mesh_units(scenarios.load(scenario, events=False))


def _wait_done(proc: Proc, out_dir: Path, units: list[str], timeout_s: float, each=None) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if each is not None:
            each()
        if _peers_done(out_dir, units):
            return
        if proc.p.poll() is not None:
            if _peers_done(out_dir, units):
                return
            raise RuntimeError(f"mesh up exited early: {proc.tail()}")
        time.sleep(0.25)   # a sampling period, not a synchronisation
    raise TimeoutError(f"the run did not end within {timeout_s:.0f} s")


def _settle(d, out_dir: Path, timeout_s: float = 60.0, still_s: float = 3.0) -> None:
    """Until the page has drawn every alert the peers logged and every notice they gave
    (each reaches the console once), or nothing more came for `still_s` (a peer's alert
    from before the console subscribed, a wall-clock presence note, never reaches it: the
    results say what the page lacks, alerts_page and notices_page), or `timeout_s`."""
    alerts = sum(len(v) for v in alert_logs(out_dir).values())
    n = notice_counts(out_dir)
    notices = n["notifications"] + n["escalations"]
    end = time.monotonic() + timeout_s
    last, since = None, time.monotonic()
    while time.monotonic() < end:
        got = d.execute_script("return [window.__alertsSeen, window.__noticeLog.length]")
        if got[0] >= alerts and got[1] >= notices:
            return
        if got != last:
            last, since = got, time.monotonic()
        elif time.monotonic() - since >= still_s:
            return
        time.sleep(0.1)   # polling the page's condition


def watched(scenario: Path, out_dir: Path, speed: str = "max", screenshot: Path | None = None,
            timeout_s: float = 1200.0) -> dict:
    """The run through `mesh up --console`, the page open from the start."""
    from tests.browser import chromium
    t_start = time.monotonic()
    proc = _mesh_up(scenario, out_dir, speed, console=True)
    try:
        url = proc.wait_for("http://127.0.0.1:", 180).split()[0]
        with chromium() as d:
            d.set_window_size(1600, 1000)
            d.get(url)
            d.execute_script(LONGTASKS)
            opened_ms = d.execute_script("return Date.now()")
            rtt: list[float] = []

            def sample() -> None:
                t0 = time.perf_counter()
                d.execute_script("return document.querySelectorAll('li.story').length")
                rtt.append(1000 * (time.perf_counter() - t0))
            _wait_done(proc, out_dir, _mesh_units(scenario), timeout_s, sample)
            _settle(d, out_dir)
            page = d.execute_script("""return {lat: window.__latencies(), notices: window.__noticeLog,
                frames: window.__frames, longTasks: window.__longTasks || [], seen: window.__alertsSeen,
                firstPaint: window.__firstPaintMs, paint: window.__paint, eventMs: window.__eventMs,
                stories: window.__console.S.stories.size, quiet: window.__console.S.quiet.length,
                escalationsShown: document.querySelectorAll('#escalations li.escalation').length}""")
            d.execute_cdp_cmd("Performance.enable", {})
            metrics = {m["name"]: m["value"] for m in d.execute_cdp_cmd("Performance.getMetrics", {})["metrics"]}
            if screenshot is not None:
                screenshot.parent.mkdir(parents=True, exist_ok=True)
                d.save_screenshot(str(screenshot))
        with chromium() as d:   # a commander who opens the console at the end: the whole run in one snapshot
            d.set_window_size(1600, 1000)
            d.get(url)
            end = time.monotonic() + 60
            while d.execute_script("return window.__firstPaintMs") is None and time.monotonic() < end:
                time.sleep(0.05)
            reopened = d.execute_script("return {firstPaint: window.__firstPaintMs, paint: window.__paint, "
                                        "seen: window.__alertsSeen}")
    finally:
        proc.stop()
    lat = page["lat"]
    live = [e for e in lat if e["due_ms"] is not None and e["due_ms"] >= opened_ms]
    drawn = [e["rendered_ms"] for e in lat]
    span_s = (max(drawn) - min(drawn)) / 1000 if len(drawn) > 1 else 0.0
    notices = page["notices"]
    peers = _summaries(out_dir)
    frames = page["frames"] or []
    return {
        "peers": len(peers), "wall_s": round(time.monotonic() - t_start, 1),
        "render_latency_ms": _pcts([e["render_ms"] for e in lat if e.get("render_ms") is not None]),
        "first_paint_ms": reopened["firstPaint"], "first_paint_open_ms": page["firstPaint"],
        "first_paint_steps_ms": reopened["paint"], "alerts_reopened_page": reopened["seen"],
        "raise_to_render_ms": _pcts([e["latency_ms"] for e in live]),
        "baseline_peer_alert_latency_p99_ms": max((s.get("alert_latency_ms", {}).get("p99", 0.0)
                                                   for s in peers.values()), default=None),
        "notice_render_latency_ms": _pcts([n["rendered_ms"] - n["received_ms"] for n in notices
                                           if n.get("received_ms") is not None]),
        "alerts_page": page["seen"], "alerts_live": len(live), "stories_page": page["stories"],
        "quiet_page": page["quiet"], "notices_page": len(notices),
        "notices_page_by_kind": {k: sum(1 for n in notices if n["kind"] == k) for k in ("renotify", "escalate")},
        "escalations_shown": page["escalationsShown"],
        "alerts_per_s_pushed": round(page["seen"] / span_s, 1) if span_s else None,
        "page_rtt_ms": _pcts(rtt),
        "events_ms": {k: {"n": v[0], "ms": round(v[1], 1)} for k, v in sorted((page["eventMs"] or {}).items())},
        "frames": {"n": len(frames), "ms": _pcts([f[1] for f in frames]), "alerts_max": max((f[2] for f in frames), default=0)},
        "long_tasks": {"n": len(page["longTasks"]), "max_ms": round(max(page["longTasks"]), 1) if page["longTasks"] else 0.0,
                       "total_ms": round(sum(page["longTasks"]), 1)},
        "page_memory": {"js_heap_used_mb": round(metrics.get("JSHeapUsedSize", 0) / 2**20, 1),
                        "js_heap_total_mb": round(metrics.get("JSHeapTotalSize", 0) / 2**20, 1),
                        "dom_nodes": int(metrics.get("Nodes", 0))},
    }


def unarmed_mesh(scenario: Path, out_dir: Path, speed: str, timeout_s: float) -> None:
    """The same run without a console: the peers unarmed."""
    proc = _mesh_up(scenario, out_dir, speed, console=False)
    try:
        _wait_done(proc, out_dir, _mesh_units(scenario), timeout_s)   # a peer's summary comes after its logs are closed
    finally:
        proc.stop()


def unarmed_inprocess(scenario: Path, units: list[str]) -> dict[str, list[dict]]:
    """The same units in process, unarmed: their alerts as JSON lines would have them."""
    from saim_mesh import scenario as scenarios
    from saim_mesh.inprocess.runner import run
    sc = scenarios.load(scenario)
    logs: dict[str, list[dict]] = {u: [] for u in units}
    eas = run(sc, units)
    for ea in eas:
        logs[ea.owner] = [{"priority": a.priority, "type": a.type} for a in ea.alerts]
    return logs


def check(res: dict) -> dict:
    """Each target with the value it was checked against and whether it was met."""
    def ratio(a, b):
        return round(a / b, 3) if b else (1.0 if a == 0 else None)
    vals = {"alerts_ratio": ratio(res["alerts_mesh"], res["alerts_unarmed"]),
            "flash_ratio": ratio(res["flash_mesh"], res["flash_unarmed"]),
            "render_p99_ms": res["render_latency_ms"].get("p99"),
            "first_paint_ms": res["first_paint_ms"]}
    return {k: {"value": v, "max": TARGETS[k], "ok": v is not None and v <= TARGETS[k]} for k, v in vals.items()}


def run(scenario: Path, work: Path, speed: str = "max", baseline: str = "mesh", screenshot: Path | None = None,
        timeout_s: float = 1200.0) -> dict:
    armed_dir, bare_dir = work / "console", work / "unarmed"
    armed_dir.mkdir(parents=True, exist_ok=True)
    res: dict = {"scenario": scenario.name, "speed": speed, "baseline": baseline}
    page = watched(scenario, armed_dir, speed, screenshot, timeout_s)
    logs = alert_logs(armed_dir)
    res["alerts_mesh"], res["flash_mesh"] = _counts(logs)
    if baseline == "mesh":
        bare_dir.mkdir(parents=True, exist_ok=True)
        unarmed_mesh(scenario, bare_dir, speed, timeout_s)
        bare = alert_logs(bare_dir)
        res["unarmed_notices"] = notice_counts(bare_dir)   # unarmed: none expected
    else:
        bare = unarmed_inprocess(scenario, sorted(logs))
    res["alerts_unarmed"], res["flash_unarmed"] = _counts(bare)
    res.update(notice_counts(armed_dir))
    res["alerts_by_unit"] = {u: [len(v), len(bare.get(u, ()))] for u, v in sorted(logs.items())}
    res.update(page)
    res["targets"] = check(res)
    res["targets_met"] = all(t["ok"] for t in res["targets"].values())
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion"))
    ap.add_argument("--speed", default="max")
    ap.add_argument("--baseline", choices=("mesh", "inprocess"), default="mesh",
                    help="the unarmed run: `mesh up` without a console (default), or in process")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "console.json"))
    ap.add_argument("--screenshot", default=None, metavar="PNG")
    ap.add_argument("--timeout", type=float, default=1200.0, help="wall seconds each run may take")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-console-") as tmp:
        res = run(Path(a.scenario), Path(tmp), a.speed, a.baseline, Path(a.screenshot) if a.screenshot else None,
                  a.timeout)
    res["machine"] = {"python": platform.python_version(), "cpu": platform.processor() or platform.machine()}
    results.write(a.out, res, echo=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
