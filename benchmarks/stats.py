"""Percentiles as the benchmarks report them (n, p50, p95, p99, max), one definition."""
from __future__ import annotations


def percentiles(xs: list[float], digits: int = 1) -> dict:
    """{"n": 0} for no samples; else the nearest-rank p50/p95/p99 and the max, rounded."""
    if not xs:
        return {"n": 0}
    ys = sorted(xs)
    pick = lambda q: round(ys[min(len(ys) - 1, int(q * len(ys)))], digits)   # noqa: E731
    return {"n": len(ys), "p50": pick(0.50), "p95": pick(0.95), "p99": pick(0.99), "max": round(ys[-1], digits)}
