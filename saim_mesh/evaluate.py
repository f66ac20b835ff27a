"""Scoring alerts against a scenario's ground truth (truth.json)."""
from __future__ import annotations

from collections import Counter

from .messages import Alert
from .runner import run


PROJECTION_WINDOW_S = 600.0   # a projection counts for a violation that begins at most this much later


def _matches(a: Alert, item: dict) -> bool:
    """Same owner, an accepted type, in the window, and about the same things: a unit,
    a true hostile, or the named place (fused tracks have names of their own). A
    projection (`details.projects`: the type of the violation it foretells) matches what
    that type would, from PROJECTION_WINDOW_S before the window."""
    about = set(a.subjects) | set(a.details.get("places", ()))
    projects = a.details.get("projects")
    if projects is not None:
        ok = projects in item["accept"] and item["t0"] - PROJECTION_WINDOW_S <= a.t <= item["t1"]
    else:
        ok = a.type in item["accept"] and item["t0"] <= a.t <= item["t1"]
    return ok and a.owner == item["owner"] and not set(item["subjects"]).isdisjoint(about)


def _projections(alerts: list[Alert], incidents: list[dict]) -> dict:
    """Projected violations: how long before each violation it was foretold (lead), and
    the projections that foretold nothing (false)."""
    proj = [a for a in alerts if a.details.get("projects") is not None]
    leads, false = [], 0
    for a in proj:
        hit = [i for i in incidents if _matches(a, i)]
        if hit:
            leads.append(round(min(i["t0"] for i in hit) - a.t, 1))
        else:
            false += 1
    leads.sort()
    return {"alerts": len(proj), "false": false, "lead_s": leads,
            "lead_s_median": leads[len(leads) // 2] if leads else None}


def score(alerts: list[Alert], truth: dict) -> dict:
    incidents, situations = truth["incidents"], truth["situations"]
    missed = [i for i in incidents if not any(_matches(a, i) for a in alerts)]
    unwanted = [a for a in alerts if not any(_matches(a, s) for s in situations + incidents)]
    return {
        "projections": _projections(alerts, incidents),
        "incidents": len(incidents),
        "recall": round(1 - len(missed) / len(incidents), 4) if incidents else 1.0,
        "alerts": len(alerts),
        "unwanted": len(unwanted),
        "unwanted_share": round(len(unwanted) / len(alerts), 4) if alerts else 0.0,
        "unwanted_flash": sum(1 for a in unwanted if a.priority == "flash"),
        "missed": missed,
        "unwanted_alerts": [a.to_json_dict() for a in unwanted],
        "by_type": dict(sorted(Counter(a.type for a in alerts).items())),
    }


def evaluate(sc, config_path=None) -> dict:
    truth = sc.truth()
    owners = truth["owners"]
    eas = run(sc, owners, config_path=config_path)
    alerts = [a for ea in eas for a in ea.alerts]
    naive = run(sc, owners, config_path=config_path, voa=False)
    res = score(alerts, truth)
    res["naive_alerts"] = sum(len(ea.alerts) for ea in naive)
    res["reduction"] = round(res["naive_alerts"] / max(1, res["alerts"]), 1)
    res["owners"] = owners
    res["events"] = len(sc.events)
    res["watchman"] = {ea.owner: dict(getattr(getattr(ea.domain, "watchman", None), "stats", {})) for ea in eas}
    return res
