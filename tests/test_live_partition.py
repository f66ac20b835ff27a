"""A cut radio link on the live mesh (issue 31), end to end: two routers (the battalion's
and A company's command posts) joined by an emulated link, a source per command post
paced together, secure. The link is cut for longer than `source_silence_s` and healed:
each side declares the other's sources lost and goes on; after the heal the advanced
subscribers recover the missed frames from the publishers' caches across the routers, and
what a cache no longer holds from the source's journal (no gap), the EAs are rebuilt, and what each shows its commander equals an EA
fed the same facts with no cut, nothing shown twice."""
from __future__ import annotations

import json
import os
import signal
import threading
import time
from collections import Counter

import pytest

from saim_mesh import scenario as S
from saim_mesh.live.depend import cp_shares, depends
from saim_mesh.live.play import share
from saim_mesh.live.up import up
from saim_mesh.inprocess.runner import config_for, make_ea

from .conftest import SMALL

pytestmark = pytest.mark.timeout(600)
SPEED, UNTIL, CUT, HEAL = 30.0, 1200.0, 300.0, 900.0   # the cut lasts 20 s of wall time
UNITS = ["BN", "A2"]


def shown(alerts: list[dict]) -> list[tuple]:
    return [(a["t"], a["type"], tuple(a["subjects"]), a["message"]) for a in alerts
            if a["category"] != "system-problem" and "inhibited_by" not in a["details"]]


def uncut(sc, unit: str) -> list[tuple]:
    """An EA fed its sources' facts up to UNTIL, merged in (event time, source, seq) order."""
    ea = make_ea(sc, unit, config_for(sc, unit))
    ea.start(0.0)
    shares = cp_shares(sc)
    deps = depends(sc, ea, sorted(shares))
    merged = sorted(((m.t, n, i, m) for n in deps
                     for i, m in enumerate(share(sc, list(shares[n].units) if shares[n].units else None,
                                                 shares[n].tracks, list(shares[n].but)))
                     if m.t <= UNTIL), key=lambda x: x[:3])
    for *_, m in merged:
        ea.submit(m)
    ea.finish(sc.duration_s)
    return shown([a.to_json_dict() for a in ea.alerts])


def test_a_cut_link_heals_with_nothing_missed_and_the_uncut_alerts(tmp_path):
    sc = S.load(SMALL)
    topo = tmp_path / "topology.toml"
    topo.write_text('[[router]]\nname = "r-BN"\ncp = "BN"\n\n[[router]]\nname = "r-A"\ncp = "A"\nlinks = ["r-BN"]\n')
    walls: dict[str, float] = {}

    def on_started(sup, t0) -> None:
        def cutter():
            p = sup.procs["link-r-A-r-BN"]
            time.sleep(max(0.0, t0 + CUT / SPEED - time.time()))
            os.kill(p.pid, signal.SIGUSR1)
            walls["cut"] = time.time()
            time.sleep(max(0.0, t0 + HEAL / SPEED - time.time()))
            os.kill(p.pid, signal.SIGUSR2)
            walls["heal"] = time.time()
        threading.Thread(target=cutter, daemon=True).start()

    res = up(str(SMALL), UNITS, tmp_path / "out", speed=str(SPEED), show=False, until=UNTIL, on_started=on_started,
             topology=str(topo), link={"delay_ms": 0.0}, timeout=400, echo=lambda *a, **k: None)
    assert "heal" in walls and set(res["peers"]) == set(UNITS), res["events"]
    for u in UNITS:
        s = res["peers"][u]
        logged = [json.loads(x) for x in open(tmp_path / "out" / f"{u}.jsonl") if x.strip()]
        events = Counter(a["details"].get("event") for a in logged if a["category"] == "system-problem")
        assert events["source-lost"] >= 1 and events["source-back"] >= 1 and s["rebuilds"] >= 1, (u, events, s)
        # nothing lost: every frame beyond the publishers' caches came from the sources' journals
        assert s["gaps"] == 0 and s["misses"] <= s["fetched"], (u, s["misses"], s["fetched"], s["gaps"])
        got = shown(logged)
        assert not [k for k, n in Counter(got).items() if n > 1], f"{u}: an alert shown twice"
        assert sorted(got) == sorted(uncut(sc, u)), u
