"""CoT events per second out of the TAK gateway's core for the battalion (issue #10).

Measured in one run (written to bench/results/tak.json):
- the core (`tak.picture.Picture`): every event of scenarios/battalion in, the clock ticking
  every 2 s of scenario time, positions due every `--period` s (units, and every entity);
  CoT XML events made per second of wall time, and the scenario's wall time per hour;
- the same events turned into TAK protocol v1 (takproto, mesh framing) per second;
- alerts: CoT alert events made per second from a fixed set of alerts;
- baselines from the same run: ElementTree building and serialising one fixed event
  (what any CoT producer pays), and takproto converting one fixed event.
"""
from __future__ import annotations

import argparse
import platform
import time
from datetime import datetime, timezone

from saim_mesh.protocol import messages as M
from saim_mesh import scenario as S
from saim_mesh.tak import cot as C
from saim_mesh.tak.picture import Options, Picture
from . import results

from . import ROOT

EPOCH = datetime(2026, 5, 1, 6, 0, 0, tzinfo=timezone.utc)
TICK_S = 2.0


def core(sc, period: float, entities: bool) -> dict:
    pic = Picture(sc, Options(period_s=period, entities=entities, epoch=EPOCH))
    out: list[bytes] = []
    next_tick = 0.0
    t0 = time.perf_counter()
    out += pic.overlay_events(0.0)
    for ev in sc.events:
        while ev.t >= next_tick:
            pic.clock(next_tick)
            out += pic.due()
            next_tick += TICK_S
        pic.message(ev)
    pic.clock(sc.duration_s, end=True)
    out += pic.due(force=True)
    wall = time.perf_counter() - t0
    t1 = time.perf_counter()
    proto = [C.encode(b, "mesh") for b in out]
    wall_proto = time.perf_counter() - t1
    return {"period_s": period, "entities": entities, "input_messages": len(sc.events), "events": len(out),
            "by_kind": dict(sorted(pic.counts.items())), "wall_s": round(wall, 3),
            "events_per_s": round(len(out) / wall), "xml_bytes_mean": round(sum(map(len, out)) / len(out)),
            "proto_events_per_s": round(len(proto) / wall_proto),
            "proto_bytes_mean": round(sum(map(len, proto)) / len(proto)),
            "wall_s_per_scenario_hour": round(wall / (sc.duration_s / 3600.0), 3)}


def alerts(sc, n: int = 5000) -> dict:
    pic = Picture(sc, Options(epoch=EPOCH))
    for ev in sc.events[:20000]:
        pic.message(ev)
    units = [u for u in sc.taskorg.units][:20]
    proto = [M.Alert(100.0 + i, units[i % len(units)], "out-of-position", "plan-constraint-violated",
                     ("flash", "immediate", "priority", "routine")[i % 4], (units[(i + 1) % len(units)],),
                     f"alert {i}", {"id": f"{units[i % len(units)]}/{i}"}) for i in range(n)]
    t0 = time.perf_counter()
    out = [pic.alert_event(a) for a in proto]
    wall = time.perf_counter() - t0
    return {"alerts": n, "events_per_s": round(len(out) / wall)}


def baseline(n: int = 20000) -> dict:
    """One fixed event: ElementTree build + serialise; takproto XML -> protobuf."""
    t = EPOCH
    from datetime import timedelta
    t0 = time.perf_counter()
    for _ in range(n):
        xml = C.event("u", "a-f-G-U-C", -116.5, 35.2, t, t + timedelta(minutes=5), callsign="2 PLT, A CO",
                      remarks="platoon A2")
    build = time.perf_counter() - t0
    t1 = time.perf_counter()
    for _ in range(n):
        C.encode(xml, "mesh")
    conv = time.perf_counter() - t1
    return {"events": n, "elementtree_events_per_s": round(n / build), "takproto_events_per_s": round(n / conv)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="bench_tak", description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion"))
    ap.add_argument("--period", type=float, default=10.0)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "tak.json"))
    a = ap.parse_args(argv)
    sc = S.load(a.scenario)
    res = {"scenario": sc.name, "duration_s": sc.duration_s, "python": platform.python_version(),
           "machine": platform.machine(), "cores": __import__("os").cpu_count(),
           "units": core(sc, a.period, False), "units_and_entities": core(sc, a.period, True),
           "alerts": alerts(sc), "baseline": baseline()}
    u, b = res["units_and_entities"], res["baseline"]
    res["summary"] = (f"{u['events_per_s']} CoT events/s out of the core ({u['events']} events for "
                      f"{sc.duration_s / 3600:.1f} h of {sc.name}, units and entities every {a.period:g} s); "
                      f"baseline ElementTree {b['elementtree_events_per_s']}/s, takproto "
                      f"{b['takproto_events_per_s']}/s for one fixed event")
    results.write(a.out, res, echo=True, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
