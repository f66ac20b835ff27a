"""Traffic figures for docs/history/deployment-notes.md, measured on the committed battalion scenario.

    PYTHONPATH=. .venv/bin/python scripts/deployment_rates.py [--alerts FILE] [--overhead]
        [--boundary BRIGADE_SCENARIO] [--json OUT]

* per key family: messages/s and bytes/s (payload as `messages.encode` gives it: a live
  source carries its messages inside its frames, `saim_mesh/live/frames.py`, so no
  per-message attachment or envelope), for the whole battalion and per friendly entity;
  the key's length beside it;
* authority messages (orders, reorganizations, confirmations, calls for fire) per hour;
* alerts (from `saim-mesh run scenarios/battalion --ea <every mesh unit> --out FILE`):
  per EA per hour and their encoded size; the control traffic (an EA's pace ack to a source);
* `--overhead`: Zenoh's bytes per message on a router link, measured: two routers in
  this process joined through `linkemu.Link` (its byte counters: TCP payload, so no
  TCP/IP or radio headers), a client publishing the battalion's real position keys and
  payloads behind one router, a client subscribing behind the other; paced (one message
  per Zenoh frame, as at 1x) and in a burst (Zenoh batches);
* `--boundary`: on a multi-battalion scenario (the brigade, from i14-gen's generator),
  the share of each battalion's position reports that fall in another battalion's
  geographic interest (cells within `radius_m` of one of its leaf units' centroids,
  recomputed every 30 s), i.e. what a neighbour pulls across the brigade router.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.append(str(ROOT))   # after PYTHONPATH: another checkout may load newer scenarios

from dissemination.keyspace import KeySpace, cells_within, place  # noqa: E402
from saim_mesh.protocol import messages as M  # noqa: E402
from saim_mesh import scenario as S  # noqa: E402
from saim_mesh.protocol import wire as W  # noqa: E402

ATTACHMENT = 8                            # what the --overhead probe attaches to each put
AUTHORITY = ("ord", "org", "msn", "cff")


def rates(sc, root: str = "saim/battalion") -> dict:
    ks = KeySpace.of(sc, root)
    n_ent = len(sc.taskorg.entity_unit)
    dur = sc.duration_s
    n, b, kb = Counter(), Counter(), Counter()
    for ev in sc.events:
        k = ks.key(ev, sc.taskorg, sc.projection)
        fam = ks.family(k)
        size = len(M.encode(ev))
        n[fam] += 1
        b[fam] += size
        kb[fam] += len(k)
    fams = {}
    for f in sorted(n, key=lambda f: -b[f]):
        fams[f] = {"messages": n[f], "msg_per_s": n[f] / dur, "bytes_per_s": b[f] / dur,
                   "bytes_per_msg": b[f] / n[f], "key_chars": kb[f] / n[f],
                   "per_entity_msg_per_s": n[f] / dur / n_ent, "per_entity_bytes_per_s": b[f] / dur / n_ent,
                   "per_hour": n[f] / dur * 3600}
    return {"scenario": sc.name, "entities": n_ent, "units": len(sc.taskorg.units), "duration_s": dur,
            "events": len(sc.events), "families": fams,
            "total_msg_per_s": sum(n.values()) / dur, "total_bytes_per_s": sum(b.values()) / dur,
            "authority_per_hour": {f: n[f] / dur * 3600 for f in AUTHORITY}}


def alerts(path: Path, dur: float) -> dict:
    per, size, prio = Counter(), [], Counter()
    for line in open(path):
        d = json.loads(line)
        a = M.Alert.from_dict(d)
        per[a.owner] += 1
        size.append(len(M.encode(a)) + len(f"saim/battalion/alert/{a.owner}/{a.type}"))
        prio[a.priority] += 1
    h = dur / 3600
    return {"alerts": sum(per.values()), "eas": len(per),
            "per_ea_per_hour": {u: c / h for u, c in sorted(per.items(), key=lambda x: -x[1])},
            "mean_per_ea_per_hour": sum(per.values()) / len(per) / h,
            "bytes_mean": sum(size) / len(size), "bytes_max": max(size), "by_priority": dict(prio)}


def control() -> dict:
    """An EA's pace ack to a source it depends on (`saim_mesh/live/pace.py`)."""
    return {"ack_bytes": len(W.encode(W.make(W.Ack, t=2700.0)))}


def overhead(sc, n: int = 3000) -> dict:
    """Bytes on the router link per message, beyond payload + an 8-byte attachment (Zenoh framing + key)."""
    import zenoh
    from saim_mesh.launch import zenoh_config
    from saim_mesh.net.linkemu import Link
    ks = KeySpace.of(sc, "saim/battalion")
    msgs = [(ks.key(ev, sc.taskorg, sc.projection), M.encode(ev)) for ev in sc.events
            if type(ev).__name__ == "LocationReport"][:n]
    pa, pb = zenoh_config.free_port(), zenoh_config.free_port()
    link = Link(0, pa).start()
    pl = link.listen_port
    ra = zenoh.open(zenoh_config.config(listen=[f"tcp/127.0.0.1:{pa}"], mode="router"))
    rb = zenoh.open(zenoh_config.config(listen=[f"tcp/127.0.0.1:{pb}"], connect=[f"tcp/127.0.0.1:{pl}"], mode="router"))
    pub = zenoh.open(zenoh_config.config(connect=[f"tcp/127.0.0.1:{pa}"], mode="client"))
    sub = zenoh.open(zenoh_config.config(connect=[f"tcp/127.0.0.1:{pb}"], mode="client"))
    got = []
    s = sub.declare_subscriber("saim/battalion/pos/**", lambda smp: got.append(1))
    time.sleep(2.0)
    pubs = {k: pub.declare_publisher(k) for k in {k for k, _ in msgs}}

    def total() -> int:
        st = link.stats()
        return st["up"]["bytes"] + st["down"]["bytes"]

    def run(pace: float) -> dict:
        got.clear()
        time.sleep(1.0)
        b0, t0 = total(), time.monotonic()
        for i, (k, p) in enumerate(msgs):
            pubs[k].put(p, attachment=i.to_bytes(8, "big"))
            if pace:
                time.sleep(pace)
        while len(got) < len(msgs) and time.monotonic() - t0 < 60:
            time.sleep(0.05)
        time.sleep(0.5)
        wire = total() - b0
        body = sum(len(p) + ATTACHMENT for _, p in msgs)
        return {"messages": len(msgs), "delivered": len(got), "wire_bytes": wire, "payload_bytes": body,
                "overhead_per_msg": (wire - body) / len(msgs), "key_chars_mean": sum(len(k) for k, _ in msgs) / len(msgs)}

    idle0 = total()
    time.sleep(3.0)
    idle = (total() - idle0) / 3.0
    out = {"idle_link_bytes_per_s": idle, "paced_2ms": run(0.002), "burst": run(0.0),
           "note": "TCP payload bytes both directions (linkemu counters), tcp without TLS, one fresh "
                   "declared publisher per key: the first use of a key may carry it in full"}
    s.undeclare()
    for x in (pub, sub, rb, ra):
        x.close()
    link.stop()
    return out


def boundary(path: str, radius: float = 3000.0, period: float = 30.0) -> dict:
    """Per battalion: its reports in another battalion's (cell-based) interest, and what each pulls in."""
    sc = S.load(path)
    to, proj = sc.taskorg, sc.projection
    top = next(u for u in to.units if to.path(u).count("/") == 0)
    bns = [u for u in to.children(top) if getattr(to.units[u], "kind", "") == "battalion"]
    side_of = {}
    for u in to.units:
        p = to.path(u).split("/")
        side_of[u] = p[1] if len(p) > 1 and p[1] in bns else "troops"
    pos: dict[str, tuple[float, float]] = {}
    interest: dict[str, set[str]] = {b: set() for b in bns}
    nxt = 0.0
    out_n, cross_n = Counter(), Counter()
    pulled = Counter()
    for ev in sc.events:
        if type(ev).__name__ != "LocationReport":
            continue
        if ev.t >= nxt:
            cent = defaultdict(list)
            for e, xy in pos.items():
                cent[to.entity_unit[e]].append(xy)
            interest = {b: set() for b in bns}
            for u, pts in cent.items():
                if side_of[u] in interest:
                    x = sum(p[0] for p in pts) / len(pts)
                    y = sum(p[1] for p in pts) / len(pts)
                    interest[side_of[u]] |= cells_within(x, y, radius, sc.meta.get("keyspace", {}).get("cell_m", 2000.0))
            nxt = ev.t + period
        xy = proj.to_xy(ev.lon, ev.lat)
        pos[ev.entity] = xy
        side = side_of.get(to.entity_unit.get(ev.entity, ""), "troops")
        c = place(*xy).split("/")[1]
        out_n[side] += 1
        needers = [b for b in bns if b != side and c in interest[b]]
        if needers:
            cross_n[side] += 1
        for b in needers:
            pulled[b] += 1
    return {"scenario": sc.name, "battalions": bns, "entities": len(to.entity_unit),
            "reports_by_side": dict(out_n),
            "share_needed_by_a_neighbour": {s: cross_n[s] / out_n[s] for s in out_n},
            "pulled_in_share_of_own": {b: pulled[b] / out_n[b] for b in bns},
            "note": "cells within radius of each leaf unit's centroid (a box, as cells_within); no block "
                    "rounding, no watched areas: a lower bound of the geographic interest"}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion"))
    ap.add_argument("--alerts", help="alerts JSONL of `saim-mesh run` with every mesh unit's EA")
    ap.add_argument("--overhead", action="store_true")
    ap.add_argument("--boundary")
    ap.add_argument("--json")
    a = ap.parse_args()
    sc = S.load(a.scenario)
    res = {"rates": rates(sc), "control": control()}
    r = res["rates"]
    print(f"{r['scenario']}: {r['entities']} entities, {r['events']} events, {r['duration_s']:.0f} s")
    print(f"{'family':6} {'msgs':>7} {'msg/s':>8} {'B/s':>9} {'B/msg':>6} {'key':>5} "
          f"{'msg/s/ent':>10} {'B/s/ent':>8}")
    for f, d in r["families"].items():
        print(f"{f:6} {d['messages']:7d} {d['msg_per_s']:8.3f} {d['bytes_per_s']:9.1f} {d['bytes_per_msg']:6.0f} "
              f"{d['key_chars']:5.0f} {d['per_entity_msg_per_s']:10.5f} {d['per_entity_bytes_per_s']:8.3f}")
    print(f"total  {r['events']:7d} {r['total_msg_per_s']:8.3f} {r['total_bytes_per_s']:9.1f}")
    print("authority per hour:", {k: round(v, 1) for k, v in r["authority_per_hour"].items()})
    print("control:", res["control"])
    if a.alerts:
        res["alerts"] = al = alerts(Path(a.alerts), sc.duration_s)
        print(f"alerts: {al['alerts']} from {al['eas']} EAs, {al['mean_per_ea_per_hour']:.1f}/h per EA mean, "
              f"{al['bytes_mean']:.0f} B mean (max {al['bytes_max']}) with key;",
              {u: round(v, 1) for u, v in al["per_ea_per_hour"].items()}, al["by_priority"])
    if a.overhead:
        res["overhead"] = o = overhead(sc)
        print("zenoh overhead:", json.dumps(o))
    if a.boundary:
        res["boundary"] = bd = boundary(a.boundary)
        print("boundary:", json.dumps(bd))
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
