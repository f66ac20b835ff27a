"""Seeded, deterministic battalion scenario generator.

A battalion (three line companies of three platoons of four squads, company and
battalion HQs, a recon and a mortar platoon) moves north over Fort Irwin (UTM 11N):
road march to PL BLUE, attack to the objectives, then defend. Hostile groups come
down avenues of approach. Labelled incidents are injected so that every alert type
occurs; the `oracle` package derives the ground truth from the simulated true state.
"""
from __future__ import annotations

import gzip
import io
import json
from pathlib import Path

import numpy as np

from ea_agent.core.geo import Projection

from .battle_plan import DURATION, EPSG, ORIGIN_LONLAT, overlay_features, plan_doc  # noqa: F401 (the battle's facts)
from .sim import INCIDENTS, MAX_GROUND_MPS, SENSOR_PERIOD, SENSORS, Sim, build_sim, hits  # noqa: F401


# ------------------------------------------------------------------ events
def events(sim: Sim, proj: Projection, ox: float, oy: float, sensors: bool = False) -> list[dict]:
    rng = np.random.default_rng(sim.seed + 1)
    ev: list[tuple[float, int, dict]] = []
    seq = 0

    def ll(x, y):
        lon, lat = proj.to_lonlat(x + ox, y + oy)
        return round(float(lon), 7), round(float(lat), 7)
    ents = sorted(sim.entity_leaf)
    phase = {e: round(sim.report_phase[e], 2) for e in ents}
    for e in ents:
        last_true = None
        last_rep = None
        t = phase[e]
        while t < sim.duration:
            x, y = sim.entity_pos(e, t)
            if sim.reports_at(e, t):
                moved = last_true is None or np.hypot(x - last_true[0], y - last_true[1]) > 0.5
                if moved:
                    nx, ny = rng.normal(0, 2.0, 2)
                    last_rep = ll(x + nx, y + ny)
                last_true = (x, y)
                seq += 1
                ev.append((round(t, 2), seq, {"kind": "location", "t": round(t, 2), "entity": e,
                                               "lon": last_rep[0], "lat": last_rep[1]}))
            t += sim.report_s
    for t, d in (hits(sim, proj, ox, oy) if sensors else []):
        seq += 1
        ev.append((t, seq, d))
    for h in ([] if sensors else sim.hostiles.values()):
        t = h.appear + 3.0
        while t < min(h.vanish, sim.duration):
            x, y = h.pos(t)
            lon, lat = ll(x, y)
            seq += 1
            ev.append((round(t, 2), seq, {"kind": "track", "t": round(t, 2), "track": h.id, "lon": lon, "lat": lat,
                                           "strength": h.strength, "source": "fusion"}))
            t += 10.0
        if h.appear < h.vanish < sim.duration:
            x, y = h.pos(h.vanish - 1e-6)
            lon, lat = ll(x, y)
            seq += 1
            ev.append((h.vanish, seq, {"kind": "track", "t": h.vanish, "track": h.id, "lon": lon, "lat": lat,
                                        "strength": 0, "source": "fusion"}))
    if sim.order is not None:
        seq += 1
        ev.append((sim.order["t"], seq, {"kind": "order", "t": sim.order["t"], "action": "execute-plan",
                                         "plan": sim.order["plan"], "issuer": sim.order["issuer"]}))
    for o in sim.mission_orders:
        seq += 1
        ev.append((o["t"], seq, {"kind": "order", "t": o["t"], "action": f"{o['phase']}-mission", "plan": "main",
                                 "issuer": o["issuer"], "mission": o["mission"]}))
    for t, mid, unit, phase_ in sim.confirmations:
        seq += 1
        ev.append((t, seq, {"kind": "mission", "t": t, "mission": mid, "unit": unit, "phase": phase_}))
    for c in sim.cffs:
        lon, lat = ll(c["x"], c["y"])
        seq += 1
        ev.append((c["t"], seq, {"kind": c["kind"], "t": c["t"], "cff": c["cff"], "requester": c["requester"],
                                 "lon": lon, "lat": lat, "radius_m": c["radius_m"]}))
    ev.sort(key=lambda e: (e[0], e[1]))
    return [e[2] for e in ev]


def lonlat_features(feats: list[dict], proj: Projection, ox: float, oy: float) -> list[dict]:
    """The overlay's features from local metres (origin at ox, oy) to rounded lon/lat."""
    def to_ll(coords):
        if isinstance(coords[0], (int, float)):
            lon, lat = proj.to_lonlat(coords[0] + ox, coords[1] + oy)
            return [round(float(lon), 7), round(float(lat), 7)]
        return [to_ll(c) for c in coords]
    return [{**f, "geometry": {"type": f["geometry"]["type"], "coordinates": to_ll(f["geometry"]["coordinates"])}}
            for f in feats]


def write_events(out: Path, evs) -> None:
    """events.jsonl.gz, byte-identical for the same events (no time stamp in the gzip header)."""
    buf = io.BytesIO()
    with gzip.GzipFile(fileobj=buf, mode="wb", mtime=0) as gz:
        for e in evs:
            gz.write((json.dumps(e, separators=(",", ":")) + "\n").encode())
    for stale in ("events.jsonl", "events.jsonl.gz"):
        (out / stale).unlink(missing_ok=True)
    (out / "events.jsonl.gz").write_bytes(buf.getvalue())


def write(out: Path, small: bool = False, seed: int = 7, sensors: bool = False, incidents: str = "scripted") -> dict:
    """Generate the scenario folder `out`; returns a summary."""
    from . import oracle
    out.mkdir(parents=True, exist_ok=True)
    proj = Projection(EPSG)
    ox, oy = proj.to_xy(*ORIGIN_LONLAT)
    sim = build_sim(small, seed, incidents)
    if sensors:   # the oracle holds the EAs to what the sensors could see
        sim.sensors = [(sid, rng_m) for sid, _g, _o, _k, rng_m, *_ in SENSORS]
    feats = overlay_features()
    ll_feats = lonlat_features(feats, proj, ox, oy)
    meta = {"name": ("battalion-small" if small else "battalion") + ("-sensors" if sensors else "")
            + (f"-random-{seed}" if incidents == "random" else ""),
            "epsg": EPSG, "duration_s": DURATION,
            "generator": {"seed": seed, "small": small, "sensors": sensors, "incidents": incidents}, "default_eas": ["BN", "A", "B", "C", "A2"],
            "description": "1st BN moves to PL BLUE, attacks OBJ A/B/C and defends (Fort Irwin, UTM 11N)"}
    if sensors:
        meta["fusion"] = {"groups": {g: sorted(sid for sid, grp, *_ in SENSORS if grp == g) for g in ("F", "N")},
                          "max_speed_mps": MAX_GROUND_MPS,
                          "sensors": [{"id": sid, "group": g, "owner": o, "kind": k, "range_m": r, "pd": pd,
                                       "sigma_m": sg, "false_alarms_per_scan": fa, "period_s": SENSOR_PERIOD}
                                      for sid, g, o, k, r, pd, sg, fa in SENSORS]}
    (out / "scenario.json").write_text(json.dumps(meta, indent=1) + "\n")
    (out / "overlay.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": ll_feats}) + "\n")
    plan = plan_doc(sim)
    (out / "plan.json").write_text(json.dumps(plan, indent=1) + "\n")
    evs = events(sim, proj, ox, oy, sensors)
    write_events(out, evs)
    truth = oracle.ground_truth(sim, feats, plan, meta["default_eas"])
    truth["incidents_injected"] = INCIDENTS if incidents == "scripted" else sim.drawn
    (out / "truth.json").write_text(json.dumps(truth, indent=1) + "\n")
    return {"events": len(evs), "entities": len(sim.entity_leaf), "incidents": len(truth["incidents"]),
            "situations": len(truth["situations"])}
