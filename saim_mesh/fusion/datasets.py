"""Seeded sensor data sets for the fusion benchmark, in local metres: what the battalion
scenario does not have (lone vehicles, aircraft at 100-300 m/s, crossing paths, slow
aircraft that orbit and turn hard).

Each sensor scans every `period` s at its own phase; a truth within its range is
detected at most once a scan (probability pd) with N(0, sigma^2) noise per axis, and
each scan adds Poisson false alarms uniform over the sensor's disc. A data set whose
truths have heights (`alt`, metres above ground) has sensors that measure it (3D
radars): each hit carries the truth's height with N(0, alt_sigma^2) noise, a false
alarm a height uniform in [0, 3000] m."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

Path = Callable[[float], tuple[float, float] | None]


@dataclass(frozen=True)
class Hit:
    t: float
    sensor: str
    x: float
    y: float
    truth: str | None   # None: a false alarm
    alt: float | None = None   # height above ground, where the sensor measures it


@dataclass(frozen=True)
class DataSet:
    name: str
    truths: dict[str, Path]
    hits: list[Hit]
    sigma: dict[str, float]
    duration_s: float
    domain: dict[str, str]
    alt: dict[str, float] | None = None   # each truth's height above ground, if the sensors measure it


def _leg_path(t0: float, x0: float, y0: float, legs: list[tuple[float, float, float]]) -> Path:
    """Piecewise constant velocity: legs of (duration s, vx, vy) from (x0, y0) at t0."""
    def pos(t: float):
        if t < t0:
            return None
        x, y, s = x0, y0, t0
        for d, vx, vy in legs:
            if t <= s + d:
                return x + vx * (t - s), y + vy * (t - s)
            x, y, s = x + vx * d, y + vy * d, s + d
        return None
    return pos


def _turn_path(t0: float, x0: float, y0: float, speed: float, heading: float, turns: list[tuple[float, float, float]],
               end: float) -> Path:
    """Constant speed; `turns` = (start t, duration s, degrees): a coordinated turn. Sampled every 0.5 s."""
    ts = np.arange(t0, end + 0.5, 0.5)
    h = np.full(len(ts), math.radians(heading))
    for ts0, dur, deg in turns:
        k = (ts >= ts0)
        frac = np.clip((ts - ts0) / dur, 0.0, 1.0)
        h = np.where(k, h + math.radians(deg) * frac, h)
    vx, vy = speed * np.sin(h), speed * np.cos(h)
    xs = x0 + np.concatenate([[0.0], np.cumsum(vx[:-1] * 0.5)])
    ys = y0 + np.concatenate([[0.0], np.cumsum(vy[:-1] * 0.5)])

    def pos(t: float):
        if t < t0 or t > end:
            return None
        return float(np.interp(t, ts, xs)), float(np.interp(t, ts, ys))
    return pos


def _scan(name: str, truths: dict[str, Path], sensors: list[tuple[str, float, float, float, float, float, float]],
          duration: float, seed: int, domain: dict[str, str], period: float = 5.0,
          alt: dict[str, float] | None = None, alt_sigma: float = 30.0) -> DataSet:
    """sensors: (id, x, y, range m, pd, sigma m, false alarms per scan). Heights draw from
    their own generator, so a data set's positions do not depend on whether it has them."""
    rng = np.random.default_rng(seed)
    hrng = np.random.default_rng(seed + 1000)
    hits: list[Hit] = []

    def height(tid: str | None) -> float | None:
        if alt is None:
            return None
        return float(hrng.uniform(0, 3000)) if tid is None else round(alt[tid] + float(hrng.normal(0, alt_sigma)), 1)
    for sid, sx, sy, rng_m, pd, sigma, fa in sensors:
        t = float(rng.uniform(0, period))
        while t < duration:
            for tid in sorted(truths):
                p = truths[tid](t)
                if p is not None and math.hypot(p[0] - sx, p[1] - sy) <= rng_m and rng.random() < pd:
                    nx, ny = rng.normal(0, sigma, 2)
                    hits.append(Hit(round(t, 3), sid, p[0] + nx, p[1] + ny, tid, height(tid)))
            for _ in range(rng.poisson(fa)):
                r, a = rng_m * math.sqrt(rng.random()), rng.uniform(0, 2 * math.pi)
                hits.append(Hit(round(t, 3), sid, sx + r * math.cos(a), sy + r * math.sin(a), None, height(None)))
            t += period
    hits.sort(key=lambda h: (h.t, h.sensor))
    return DataSet(name, truths, hits, {s[0]: s[5] for s in sensors}, duration, domain, alt)


def lone(seed: int = 1) -> DataSet:
    """Six lone ground vehicles at 3-15 m/s, two of them turning 90 degrees; 3 sensors."""
    T = 900.0
    truths = {
        "V1": _leg_path(0, 0, 0, [(900, 5.0, 0.0)]),
        "V2": _leg_path(30, 1000, 3000, [(300, 8.0, 0.0), (600, 0.0, -8.0)]),
        "V3": _leg_path(60, 6000, 1000, [(840, -3.0, 3.0)]),
        "V4": _leg_path(0, 2000, -1500, [(400, 12.0, 0.0), (500, 0.0, 12.0)]),
        "V5": _leg_path(100, 8000, -2000, [(800, -15.0, 0.0)]),
        "V6": _leg_path(0, 4000, 4000, [(900, 0.0, -4.0)]),
    }
    sensors = [("S1", 1500, 500, 6000, 0.85, 25.0, 0.1), ("S2", 6500, 1500, 6000, 0.85, 25.0, 0.1),
               ("S3", 4000, -3000, 6000, 0.85, 25.0, 0.1)]
    return _scan("lone", truths, sensors, T, seed, {k: "ground" for k in truths})


def air(seed: int = 2) -> DataSet:
    """Four aircraft at 100, 150, 250 and 300 m/s, one in a 3 g turn; 2 radars."""
    T = 600.0
    truths = {
        "A1": _turn_path(0, -30000, -10000, 100.0, 60.0, [], T),
        "A2": _turn_path(0, 30000, 20000, 150.0, 225.0, [(200, 10, 90.0)], T),   # ~24 m/s^2 for 10 s
        "A3": _turn_path(20, -40000, 30000, 250.0, 100.0, [], T),
        "A4": _turn_path(50, 40000, -30000, 300.0, 300.0, [], 300.0),
    }
    sensors = [("R1", 0, 0, 80000, 0.9, 60.0, 0.2), ("R2", 20000, 10000, 80000, 0.9, 60.0, 0.2)]
    return _scan("air", truths, sensors, T, seed, {k: "air" for k in truths})


def crossing(seed: int = 3) -> DataSet:
    """Two pairs of lone vehicles crossing (X paths, within 5 s of each other) and a pair
    on parallel paths 300 m apart; 2 sensors. (Vehicles within the tracker's birth radius,
    250 m, that move together are one group track with strength 2, by design.)"""
    T = 600.0
    truths = {
        "X1": _leg_path(0, 0, 0, [(600, 10.0, 10.0)]),
        "X2": _leg_path(0, 0, 3000, [(600, 10.0, -10.0)]),          # crosses X1 at t=150
        "X3": _leg_path(0, 5000, -1000, [(600, 0.0, 9.0)]),
        "X4": _leg_path(0, 3650, 1700, [(600, 9.0, 0.0)]),           # crosses X3 at about t=150
        "P1": _leg_path(0, 1000, -2000, [(600, 8.0, 0.0)]),
        "P2": _leg_path(0, 1000, -1700, [(600, 8.0, 0.0)]),          # 300 m beside P1 (closer: one group)
    }
    sensors = [("S1", 2000, 0, 6000, 0.85, 25.0, 0.1), ("S2", 5000, 1500, 6000, 0.85, 25.0, 0.1)]
    return _scan("crossing", truths, sensors, T, seed, {k: "ground" for k in truths})


def orbit(seed: int = 4) -> DataSet:
    """Four slow aircraft that orbit and turn hard, what ground-vehicle process noise loses
    at every turn; 2 short-range 3D radars (heights measured).
    O1: a UAV at 35 m/s orbiting on a 1 km radius (2 deg/s, 1.2 m/s^2) at 1,500 m;
    O2: a helicopter at 30 m/s at 200 m, legs of 60-90 s joined by 90-180 deg turns in
        8-10 s (up to 18 deg/s, 9.4 m/s^2);
    O3: a light aircraft at 55 m/s at 1,000 m flying a racetrack (180 deg turns in 30 s,
        6 deg/s, 5.8 m/s^2, between 60 s legs);
    O4: a slow aircraft at 45 m/s at 800 m: a 270 deg turn in 15 s (18 deg/s, 14 m/s^2),
        a leg, then a tight orbit (600 m radius, 4.3 deg/s)."""
    T = 900.0
    truths = {
        "O1": _turn_path(0, -6000, 2000, 35.0, 90.0, [(0, T, math.degrees(35.0 / 1000.0 * T))], T),
        "O2": _turn_path(30, 4000, -8000, 30.0, 0.0, [(120, 8, 90.0), (210, 10, -180.0), (290, 8, 90.0),
                                                      (380, 10, 180.0), (470, 8, -90.0), (560, 10, 180.0),
                                                      (650, 8, 90.0), (740, 10, -180.0)], 840.0),
        "O3": _turn_path(0, 8000, 6000, 55.0, 270.0, [(60 + 90 * k, 30, 180.0) for k in range(9)], T),
        "O4": _turn_path(60, -2000, -9000, 45.0, 45.0, [(150, 15, 270.0), (300, 540, math.degrees(45.0 / 600.0 * 540))],
                         T),
    }
    alt = {"O1": 1500.0, "O2": 200.0, "O3": 1000.0, "O4": 800.0}
    sensors = [("R1", 0, 0, 30000, 0.9, 40.0, 0.2), ("R2", 8000, -4000, 30000, 0.9, 40.0, 0.2)]
    return _scan("orbit", truths, sensors, T, seed, {k: "air" for k in truths}, alt=alt)


DATASETS: dict[str, Callable[[int], DataSet]] = {"lone": lone, "air": air, "crossing": crossing, "orbit": orbit}
