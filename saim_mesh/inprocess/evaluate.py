"""Scoring alerts against a scenario's ground truth (truth.json)."""
from __future__ import annotations

import math
from collections import Counter

from ..protocol.messages import Alert
from .runner import run


PROJECTION_WINDOW_S = 600.0   # a projection counts for a violation that begins at most this much later


def _matches(a: Alert, item: dict) -> bool:
    """Same owner, an accepted type, in the window, and about the same things: a unit,
    a true hostile, or the named place (fused tracks have names of their own); where
    the incident says what an alert must be `about` (a threatened unit), about that. A
    projection (`details.projects`: the type of the violation it foretells) matches what
    that type would, from PROJECTION_WINDOW_S before the window (and, where the truth
    accepts the projection's own type, in that item's window)."""
    about = set(a.subjects) | set(a.details.get("places", ()))
    projects = a.details.get("projects")
    if projects is not None and a.type not in item["accept"]:
        ok = projects in item["accept"] and item["t0"] - PROJECTION_WINDOW_S <= a.t <= item["t1"]
    else:
        ok = a.type in item["accept"] and item["t0"] <= a.t <= item["t1"]
    return ok and a.owner == item["owner"] and not set(item.get("about") or item["subjects"]).isdisjoint(about)


def _projections(alerts: list[Alert], incidents: list[dict]) -> tuple[dict, dict]:
    """Projected violations: how long before each violation it was foretold (lead: from
    the alert to when the oracle says the violation happened, its `at`; the window's
    start t0 is earlier by the slack it grants for stale reports, and can come before
    the unit has done anything), the projections raised at or after the violation they
    foretell (after_the_fact: a late alert under a misleading name), and those that
    foretold nothing (false); and the same per projected type. Where a projection
    matches several incidents, the earliest violation counts."""
    proj = [a for a in alerts if a.details.get("projects") is not None]
    leads, false = [], 0
    by_type: dict[str, dict] = {}
    for a in proj:
        b = by_type.setdefault(a.type, {"alerts": 0, "false": 0, "after_the_fact": 0, "lead_s": []})
        b["alerts"] += 1
        hit = [i for i in incidents if _matches(a, i)]
        if hit:
            lead = round(min(i.get("at", i["t0"]) for i in hit) - a.t, 1)
            leads.append(lead)
            b["lead_s"].append(lead)
            b["after_the_fact"] += lead <= 0.0
        else:
            false += 1
            b["false"] += 1
    leads.sort()
    for b in by_type.values():
        b["lead_s"].sort()
    return ({"alerts": len(proj), "false": false, "after_the_fact": sum(1 for x in leads if x <= 0.0),
             "lead_s": leads, "lead_s_median": leads[len(leads) // 2] if leads else None},
            dict(sorted(by_type.items())))


# What makes a later alert about the same story news: its severity (a detail of the alert)
# changed by at least STEP in the worse direction since the last one the user was given.
# Fixed here, apart from the EAs' VOA ratios; a type not listed is news once per story.
STEP = 1.25
# sign +1: bigger is worse; -1: smaller is worse; 0: a count, every increase is news.
SEVERITY = {  # SUO
            "out-of-position": ("distance_m", +1), "schedule": ("off_s", +1), "unknown-position": ("silent_s", +1),
            "fratricide": ("min_distance_m", -1), "distance": ("distance_m", -1), "strength": ("strength", +1),
            "monitored": ("strength", +1), "ave-of-approach": ("strength", +1), "projected-late": ("late_s", +1),
            "penetration": ("strength", +1), "escape": ("strength", 0), "band": ("off_m", +1),
            "recon-progress": ("behind_by", +1),
            # robot teams
            "stuck": ("still_s", +1), "divergent": ("distance_m", +1), "no-status": ("silent_s", +1),
            "lost-target": ("unseen_s", +1), "collision": ("clearance_m", -1), "target-visible": ("acquisition", 0)}


def _no_news(alerts: list[Alert], items: list[dict]) -> list[Alert]:
    """Alerts that repeat what their owner was already told about the same story (the same
    type about the same truth item) with no material change in severity."""
    told: dict[tuple, float | None] = {}
    out = []
    for a in sorted(alerts, key=lambda a: a.t):
        item = next((k for k, i in enumerate(items) if _matches(a, i)), None)
        if item is None:
            continue   # unwanted anyway: it matches nothing
        story = (a.owner, a.type, item, frozenset(a.subjects) | frozenset(a.details.get("places", ())))
        key, sign = SEVERITY.get(a.type, (None, 0))
        v = a.details.get(key) if key else None
        v = float(v) if isinstance(v, (int, float)) and v > 0 else None
        if story not in told:
            told[story] = v
            continue
        last = told[story]
        worse = v is not None and last is not None and (
            v > last if sign == 0 else v >= last * STEP if sign > 0 else v <= last / STEP)
        if worse:
            told[story] = v
        else:
            out.append(a)
    return out


LOW = ("priority", "routine")


def _wrong_priority(alerts: list[Alert], incidents: list[dict]) -> list[Alert]:
    """Alerts at the wrong priority, by the paper's rule (6.8: flash is for what threatens
    lives, first contact and fratricide; the rest only threatens the plan): a flash alert
    that matches no life-threatening incident, and the first alert an owner gets of a
    life-threatening incident when it is below immediate. Only where the oracle says which
    incidents threaten lives (`life`; the robot-team oracle does not)."""
    out, first = [], {}
    if not any("life" in i for i in incidents):
        return out
    for a in sorted(alerts, key=lambda a: a.t):
        hit = [k for k, i in enumerate(incidents) if _matches(a, i)]
        life = [k for k in hit if incidents[k].get("life")]
        if a.priority == "flash" and hit and not life:
            out.append(a)
        for k in life:
            first.setdefault(k, a)
    out += [a for a in first.values() if a.priority in LOW]
    return out


def _pct(xs: list[float], q: float) -> float | None:
    if not xs:
        return None
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(math.ceil(q * len(xs))) - 1)]


def score(alerts: list[Alert], truth: dict) -> dict:
    incidents, situations = truth["incidents"], truth["situations"]
    delays, missed = [], []
    for i in incidents:
        ts = [a.t for a in alerts if _matches(a, i)]
        if ts:
            delays.append(round(max(0.0, min(ts) - i.get("at", i["t0"])), 1))
        else:
            missed.append(i)
    unmatched = [a for a in alerts if not any(_matches(a, s) for s in situations + incidents)]
    repeats = _no_news(alerts, incidents + situations)
    wrong = _wrong_priority(alerts, incidents)
    unwanted = list({id(a): a for a in unmatched + repeats + wrong}.values())
    projections, projections_by_type = _projections(alerts, incidents)
    return {
        "unwanted_repeats": len(repeats),
        "wrong_priority": len(wrong),
        "projections": projections,
        "projections_by_type": projections_by_type,
        "incidents": len(incidents),
        "recall": round(1 - len(missed) / len(incidents), 4) if incidents else 1.0,
        "delay_s_median": _pct(delays, 0.5),
        "delay_s_p95": _pct(delays, 0.95),
        "alerts": len(alerts),
        "unwanted": len(unwanted),
        "unwanted_share": round(len(unwanted) / len(alerts), 4) if alerts else 0.0,
        "unwanted_flash": sum(1 for a in unwanted if a.priority == "flash"),
        "missed": missed,
        "unwanted_alerts": [a.to_json_dict() for a in unwanted],
        "by_type": dict(sorted(Counter(a.type for a in alerts).items())),
        "per_type": _per_type(incidents, missed, alerts, unwanted),
    }


def _per_type(incidents: list[dict], missed: list[dict], alerts: list[Alert], unwanted: list[Alert]) -> dict:
    """Per type: the incidents of that type and how many were missed, the alerts of that
    type and how many were unwanted (an incident's type and the alert that tells it may
    differ: a contact told merged as proximity), so a new family is judged on its own."""
    out: dict[str, dict] = {}
    for key, items in (("incidents", incidents), ("missed", missed)):
        for i in items:
            out.setdefault(i["type"], {"incidents": 0, "missed": 0, "alerts": 0, "unwanted": 0})[key] += 1
    for key, items in (("alerts", alerts), ("unwanted", unwanted)):
        for a in items:
            out.setdefault(a.type, {"incidents": 0, "missed": 0, "alerts": 0, "unwanted": 0})[key] += 1
    return dict(sorted(out.items()))


# A commander model (issue 30): how long after an urgent alert the commander acknowledges
# it (None: never). "slow" is busy fighting; "diligent" reads each flash and immediate alert.
COMMANDERS: dict[str, float | None] = {"none": None, "slow": 300.0, "diligent": 30.0}


def commander_view(sc, owners: list[str], model: str, plain: list, truth: dict, config_path=None) -> dict:
    """The EAs armed, with a modelled commander acknowledging (or not), scored on what each
    commander *saw*: alerts shown (not silenced or inhibited), re-notifications of their
    own EA's alerts and escalations from below. A notice is unwanted when its alert is.
    `plain`: the unarmed run's EAs, against which no alert's priority may differ."""
    if model not in COMMANDERS:
        raise ValueError(f"unknown commander model {model!r} (known: {', '.join(COMMANDERS)})")
    notices: list = []
    eas = run(sc, owners, config_path=config_path, armed=True, ack_after_s=COMMANDERS[model],
              notice_sinks=[notices.append])
    alerts = [a for ea in eas for a in ea.alerts]
    shown = [a for a in alerts if "silenced" not in a.details and "inhibited_by" not in a.details]
    sc_ = score(shown, truth)
    bad_ids = {a["details"].get("id") for a in sc_["unwanted_alerts"]}
    prio = {a.details.get("id"): a.priority for a in alerts}
    bad_notices = [n for n in notices if n.alert in bad_ids]
    hours = max(sc.duration_s, 1.0) / 3600.0
    per = {o: 0 for o in owners}
    for a in shown:
        per[a.owner] = per.get(a.owner, 0) + 1
    for n in notices:   # a re-notification to its owner's commander, an escalation to the superior's
        if n.to in per:
            per[n.to] += 1
    per_hour = {o: round(k / hours, 1) for o, k in per.items()}
    # the unwatched run: the alerts each commander is shown with nobody in the loop, against
    # which the notice budget (ea_agent/core/budget.py) bounds what a commander is shown
    plain_per = {o: 0 for o in owners}
    for ea in plain:
        plain_per[ea.owner] = sum(1 for a in ea.alerts if "silenced" not in a.details
                                  and "inhibited_by" not in a.details)
    ratio = {o: round(per[o] / plain_per[o], 3) if plain_per.get(o) else None for o in per}
    total = len(shown) + len(notices)
    unwanted = sc_["unwanted"] + len(bad_notices)
    same = [(a.details.get("id"), a.priority) for ea in plain for a in ea.alerts]
    return {
        "model": model, "ack_after_s": COMMANDERS[model],
        "alerts": len(alerts), "alerts_shown": len(shown),
        "renotifications": sum(n.kind == "renotify" for n in notices),
        "escalations": sum(n.kind == "escalate" for n in notices),
        "shown": total, "shown_per_commander_hour": per_hour,
        "shown_per_commander_hour_worst": max(per_hour.values(), default=0.0),
        "unwatched_per_commander_hour": {o: round(k / hours, 1) for o, k in plain_per.items()},
        "shown_over_unwatched": ratio,
        "shown_over_unwatched_worst": max((r for r in ratio.values() if r is not None), default=None),
        "notices_dropped": sum(ea.notify.budget.dropped for ea in eas),
        "unwanted": unwanted, "unwanted_share": round(unwanted / total, 4) if total else 0.0,
        "unwanted_flash": sc_["unwanted_flash"] + sum(1 for n in bad_notices if prio.get(n.alert) == "flash"),
        "recall": sc_["recall"],
        "priorities_equal": same == [(a.details.get("id"), a.priority) for a in alerts],
    }


def evaluate(sc, config_path=None, commander: str | None = None) -> dict:
    truth = sc.truth()
    owners = truth["owners"]
    eas = run(sc, owners, config_path=config_path)
    alerts = [a for ea in eas for a in ea.alerts]
    naive = run(sc, owners, config_path=config_path, voa=False)
    res = score(alerts, truth)
    res["naive_alerts"] = sum(len(ea.alerts) for ea in naive)
    nv = score([a for ea in naive for a in ea.alerts], truth)
    res["naive"] = {k: nv[k] for k in ("recall", "unwanted", "unwanted_share", "unwanted_repeats", "wrong_priority",
                                       "unwanted_flash")}
    res["reduction"] = round(res["naive_alerts"] / max(1, res["alerts"]), 1)
    res["owners"] = owners
    res["events"] = len(sc.events)
    res["watchman"] = {ea.owner: dict(getattr(getattr(ea.domain, "watchman", None), "stats", {})) for ea in eas}
    if commander is not None:
        res["commander"] = commander_view(sc, owners, commander, eas, truth, config_path)
    return res
