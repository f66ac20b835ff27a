"""Scoring alerts against a scenario's ground truth (truth.json)."""
from __future__ import annotations

from collections import Counter

from .messages import Alert
from .runner import run


def _matches(a: Alert, item: dict) -> bool:
    """Same owner, an accepted type, in the window, and about the same things: a unit,
    a true hostile, or the named place (fused tracks have names of their own)."""
    about = set(a.subjects) | set(a.details.get("places", ()))
    return (a.owner == item["owner"] and a.type in item["accept"] and item["t0"] <= a.t <= item["t1"]
            and not set(item["subjects"]).isdisjoint(about))


def score(alerts: list[Alert], truth: dict) -> dict:
    incidents, situations = truth["incidents"], truth["situations"]
    missed = [i for i in incidents if not any(_matches(a, i) for a in alerts)]
    unwanted = [a for a in alerts if not any(_matches(a, s) for s in situations + incidents)]
    return {
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
