"""Ground truth from the simulated true state, written apart from the detectors.

It samples the true world every TICK seconds (no report staleness, no GPS noise)
and says, per EA owner:
 - incidents: what happened that the owner must be told of, of which type(s), within
   which window (what happened, not what our VOA would say);
 - situations: when an alert of a type is justified at all (a real situation
   exists), so that any alert outside every situation counts as unwanted.

It is a specification, not a second copy of the EA: it imports nothing from
`ea_agent` (no mission classes, no config, no VOA policy). Thresholds are the
scenario's statement of what is worth knowing (SPEC, the figures the paper's
scenario uses); how each mission type is judged comes from the paper's definitions
(section 6.5, written out below); a threat's later incidents are labelled by fixed
severity steps of its own (CLOSER, STRONGER, EPISODE_S), not by the EA's repeat ratios.
"""
from __future__ import annotations

from .base import TruthBase
from .opportunities import Opportunities
from .places import Places
from .spec import *  # noqa: F401,F403  (the constants are part of the oracle's interface)
from .spec import TICK
from .tasks import Tasks
from .threats import Threats


class Truth(Places, Threats, Tasks, Opportunities, TruthBase):
    """The whole truth of one battle: each part adds the incidents of its alert families."""


def ground_truth(sim, feats: list[dict], plan: dict, owners: list[str]) -> dict:
    tr = Truth(sim, feats, plan, owners)
    tr.contingency()
    tr.assume()   # a follower that takes over a halted unit's mission: judged as its own from then
    for step in (tr.out_of_position, tr.fratricide, tr.unknown_position, tr.schedule, tr.coordination,
                 tr.areas, tr.proximity, tr.calls_for_fire, tr.check_families, tr.presence,
                 tr.opportunities):
        step()
    key = lambda d: (d["owner"], d["t0"], d.get("type", ""), d["subjects"])
    # what would happen after the battle's end (a deadline past it) is nobody's to tell
    ran = lambda items: [d for d in items if d["t0"] <= sim.duration]   # noqa: E731
    return {"owners": owners, "tick_s": TICK, "incidents": sorted(ran(tr.incidents), key=key),
            "situations": sorted(ran(tr.situations), key=key)}

