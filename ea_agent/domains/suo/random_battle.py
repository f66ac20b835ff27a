"""A battle drawn at random from a seed (`generate --incidents random`), so that the
alert score is measured on battles nobody tuned for (`scripts/evaluate_seeds`)."""
from __future__ import annotations

import math

import numpy as np

from .battle_plan import DURATION, LANE_X, WITHDRAW_Y
from .sim import Hostile, Sim


def draw_battle(sim: Sim, rng: np.random.Generator) -> None:
    """A battle of its own per seed: which platoons start or arrive late, attack early or
    finish late, which stray off their lane (how far, how long), which squads lose their
    radios, whether the link-up and the passage partners turn up, when R is
    resubordinated, whether the battalion orders the withdrawal plan (when, how fast each
    platoon falls back), and the enemy: how many groups, down which avenue or across
    country, when, how fast, how strong, reinforced or not; calls for fire near friendly
    units or not, confirmed or not. Every draw is recorded in `sim.drawn`."""
    d = sim.drawn
    u = lambda a, b: float(round(rng.uniform(a, b)))   # noqa: E731  whole seconds / metres
    for p in LANE_X:
        start = 300.0 + (u(0, 300) if rng.random() < 0.2 else 0.0)
        arrive = 2100.0 + (start - 300.0) + (u(0, 400) if rng.random() < 0.2 else u(-60, 20))
        attack = 2400.0 - (u(0, 250) if p == "C1" and rng.random() < 0.5 else 0.0)
        attack = max(attack, arrive + 60.0)
        end = max(3600.0 + (u(0, 300) if rng.random() < 0.15 else 0.0), attack + 600.0)
        sim.paths[p] = ([0.0, start, arrive, attack, end], [0, 0, 7000, 7000, 11000])
        if (start, arrive, attack, end) != (300.0, 2100.0, 2400.0, 3600.0):
            d.append({"kind": "timing", "unit": p, "move_start": start, "move_end": arrive, "attack_start": attack,
                      "attack_end": end})
    for p in rng.choice(sorted(LANE_X), size=int(rng.integers(0, 3)), replace=False):
        t0, ramp, hold = u(700, 1600), u(200, 400), u(60, 500)
        dx = u(300, 2600) * (1 if rng.random() < 0.5 else -1)
        sim.strays[str(p)] = ([t0, t0 + ramp, t0 + ramp + hold, t0 + 2 * ramp + hold], [0, dx, dx, 0])
        d.append({"kind": "stray", "unit": str(p), "t": t0, "dx_m": dx, "hold_s": hold})
    if rng.random() < 0.5:
        sim.detours["B1S4"] = ([], [])
    if rng.random() < 0.6:
        sim.detours["C2S4"] = ([3800, 3980, 4100, 4300], [0, 440, 440, 0])
        sim.detours["C3S4"] = ([3800, 3980, 4100, 4300], [0, -740, -740, 0])
    d.append({"kind": "coordination", "link_up_partner_comes": "B1S4" in sim.detours,
              "passage_partners_come": "C2S4" in sim.detours})
    leaves = sorted(x["id"] for x in sim.units if x.get("n") and x["id"][0] in "ABC" and "HQ" not in x["id"])
    for leaf in rng.choice(leaves, size=int(rng.integers(0, 4)), replace=False):
        t0 = u(300, 5000)
        sim.outages[str(leaf)] = (t0, t0 + u(60, 600))
        d.append({"kind": "radio-outage", "unit": str(leaf), "from": t0, "to": sim.outages[str(leaf)][1]})
    if rng.random() < 0.5:   # the battalion orders the withdrawal plan (after the passage of lines)
        t = u(4350, 4550)
        sim.order = {"t": t, "plan": "withdrawal", "issuer": "BN"}
        for p in LANE_X:
            leave = t + u(20, 120)
            sim.withdraw[p] = (leave, leave + round((11000.0 - WITHDRAW_Y) / float(rng.uniform(4.0, 6.0))))
        d.append({"kind": "order", **sim.order, "withdraw": {p: list(w) for p, w in sim.withdraw.items()}})
    # BN orders M's march (ON-ORDER; M moves at 2200): in time, long before, or never
    r = rng.random()
    if r < 0.8:
        sim.mission_orders = [{"t": 2200.0 - u(0, 25), "mission": "M-march", "phase": "start", "issuer": "BN"}]
    elif r < 0.92:
        sim.mission_orders = [{"t": 2200.0 - u(45, 240), "mission": "M-march", "phase": "start", "issuer": "BN"}]
    d.append({"kind": "mission-order", "orders": sim.mission_orders})
    sim.reorg_t = u(300, 1500)
    d.append({"kind": "reorganization", "unit": "R", "new_parent": "BN", "t": sim.reorg_t})
    for k in range(int(rng.integers(4, 9))):
        x = (float(rng.choice([2000.0, 6000.0, 10650.0])) + u(-300, 300) if rng.random() < 0.7 else u(0, 12000))
        y0, y1 = u(18500, 21000), u(11500, 17000)
        appear, speed = u(400, 4600), float(rng.uniform(2.0, 6.0))
        t1 = appear + round((y0 - y1) / speed)
        vanish = t1 + u(0, 600) if rng.random() < 0.3 else DURATION + 1
        x1 = x + u(-500, 500)
        hid, strength = f"H{k + 1}", int(rng.integers(2, 10))
        sim.hostiles[hid] = Hostile(hid, [appear, t1], [x, x1], [y0, y1], strength, appear, vanish)
        d.append({"kind": "hostile", "id": hid, "from": [x, y0], "to": [x1, y1], "appear": appear, "arrive": t1,
                  "vanish": vanish if vanish <= DURATION else None, "strength": strength})
        late = appear + u(300, 1200)
        if rng.random() < 0.3 and late < vanish - 60:
            sim.hostiles[hid + "B"] = Hostile(hid + "B", [appear, t1], [x + 50, x1 + 50], [y0 + 50, y1 + 50],
                                              int(rng.integers(2, 8)), late, vanish)
            d.append({"kind": "hostile", "id": hid + "B", "reinforces": hid, "appear": late,
                      "strength": sim.hostiles[hid + "B"].strength})
    plts = sorted(LANE_X)
    for k in range(int(rng.integers(1, 4))):
        req, t = str(rng.choice(plts)), u(2500, 5200)
        if rng.random() < 0.6:   # near another platoon
            q = str(rng.choice([p for p in plts if p != req]))
            cx, cy = sim.platoon_center(q, t)
            x, y = cx + u(-500, 500), cy + u(-500, 500)
        else:
            x, y = u(0, 12000), u(15000, 19000)
        c = {"t": t, "kind": "cff", "cff": f"CFF-{k + 1}", "requester": req, "x": x, "y": y, "radius_m": 600.0}
        sim.cffs.append(c)
        if rng.random() < 0.5:
            sim.cffs.append({**c, "kind": "cff-confirm", "t": t + u(30, 90)})
        d.append({"kind": "call-for-fire", **{k_: v for k_, v in c.items() if k_ != "kind"},
                  "confirmed": sim.cffs[-1]["kind"] == "cff-confirm"})
    sim.cffs.sort(key=lambda c: (c["t"], c["cff"]))
    _draw_tasks(sim, np.random.default_rng([sim.seed, 13]))
    _draw_opportunities(sim, np.random.default_rng([sim.seed, 17]))


def _draw_tasks(sim: Sim, rng: np.random.Generator) -> None:
    """What the mission classes of issue 34 need in some battles, from a stream of its own (the
    draws above stay what they were): A2 halting in its attack (A3, following to assume, takes
    its seizure over), B1 blocking a line instead of its position, R reconnoitring its ground
    as an area (coverage) instead of a zone (depth front to rear)."""
    d = sim.drawn
    u = lambda a, b: float(round(rng.uniform(a, b)))   # noqa: E731
    if rng.random() < 0.35:   # it stands for 260-330 s, then makes up the time to its objective
        ts, ys = sim.platoon_y_path("A2")
        at, hold = ts[3] + u(150, 400), u(260, 330)
        y = float(np.interp(at, ts, ys))
        sim.paths["A2"] = (ts[:4] + [at, at + hold, ts[4]], ys[:4] + [y, y, ys[4]])
        d.append({"kind": "halt", "unit": "A2", "t": at, "hold_s": hold, "y": y})
    sim.block_line = bool(rng.random() < 0.5)
    sim.area_recon = bool(rng.random() < 0.5)
    if sim.block_line:   # a small group infiltrating south through B1's lane, across its blocking line
        x, appear, speed = 4500.0 + u(-300, 300), u(3500, 4300), float(rng.uniform(2.5, 4.0))
        arrive = appear + round(4000.0 / speed)
        sim.hostiles["H20"] = Hostile("H20", [appear, arrive], [x, x], [13500.0, 9500.0], int(rng.integers(2, 5)),
                                      appear)
        d.append({"kind": "hostile", "id": "H20", "from": [x, 13500.0], "to": [x, 9500.0], "appear": appear,
                  "arrive": arrive, "strength": sim.hostiles["H20"].strength, "crosses": "PL-B1-BLOCK"})
    d.append({"kind": "tasks", "B1_blocks": "PL-B1-BLOCK" if sim.block_line else "BP-B1",
              "R_recon": "area-reconnaissance" if sim.area_recon else "zone-reconnaissance"})


def _draw_opportunities(sim: Sim, rng: np.random.Generator) -> None:
    """New opportunities (issue 53), from a stream of their own: a group holding OBJ-A or
    OBJ-B that withdraws north before the company takes it (objective-clear), and a group
    in EA-A or EA-B while A2 or B2 defends it that withdraws north out of it
    (enemy-withdrawn), each in the other company's lane when both are drawn. Each group
    stops short of DP2 and vanishes there (the sensors lose it) once no other group is near."""
    d = sim.drawn
    u = lambda a, b: float(round(rng.uniform(a, b)))   # noqa: E731
    used = None
    for kind, p in (("objective-clear", 0.65), ("enemy-withdrawn", 0.65)):
        if rng.random() >= p:
            continue
        co = str(rng.choice(["A", "B"])) if used is None else ("B" if used == "A" else "A")
        used = co
        x = LANE_X[f"{co}2"] + u(-150, 150)
        if kind == "objective-clear":   # on the objective from before the attack, gone as the company nears:
            y, appear, top = u(10700, 11300), u(1500, 2300), u(13000, 13400)
            # once the platoon whose vehicle sensor sees it (A2, B2) is within 2.3 km (it may halt)
            near = next((t for t in range(2900, 3250, 10)
                         if math.hypot(*np.subtract(sim.platoon_center(f"{co}2", t), (x, y))) <= 2300.0), 3250)
            leave = near + u(20, 100)
        else:                           # in the engagement area as the defence begins, then north out of it
            y, appear, leave, top = u(13100, 13600), u(3450, 3650), u(3850, 4000), u(14800, 15000)
        speed = float(rng.uniform(3.5, 5.5))
        arrive = leave + round((top - y) / speed)
        x1 = x   # straight north: away from every platoon of the company
        # vanishes once clear, where no other group is near: a track the sensors lose beside
        # another group would be continued on that group's detections (the fusion's call, not ours)
        lone = (t for t in range(int(arrive) + 30, int(arrive) + 900, 10)
                if all(math.hypot(p[0] - x1, p[1] - top) > 1500.0 for h in sim.hostiles.values()
                       if (p := h.pos(float(t))) is not None))
        vanish = float(next(lone, DURATION + 1))
        hid = f"H{31 if kind == 'objective-clear' else 32}"
        sim.hostiles[hid] = Hostile(hid, [appear, leave, arrive], [x, x, x1], [y, y, top], int(rng.integers(2, 6)),
                                    appear, vanish)
        sim.apart.add(hid)   # sensed apart: the sensors' view of the battle's other groups stays as it was
        d.append({"kind": "hostile", "id": hid, "opportunity": kind, "from": [x, y], "to": [x1, top],
                  "appear": appear, "leave": leave, "arrive": arrive, "vanish": vanish if vanish <= DURATION else None,
                  "strength": sim.hostiles[hid].strength})
