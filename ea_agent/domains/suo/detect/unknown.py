"""Unknown position: own units silent for longer than the VOI threshold, looked
for on the periodic scan (silence is the absence of messages, so no change
would ever trigger it)."""
from __future__ import annotations

import numpy as np

from ea_agent.core.alert import Candidate

from .base import Changes, Detector


class UnknownPositions(Detector):
    TYPES = {"unknown-position": "reporting-requirement"}

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        if not ch.rescan:
            return
        dom = self.dom
        thr = float(dom.voi_cfg["unknown_position_s"])
        last_by_leaf = np.zeros(len(dom.leaves))
        np.maximum.at(last_by_leaf, dom.pic.ent_leaf_i, np.array(dom.pic.seen))
        for k in np.nonzero(t - last_by_leaf > thr)[0].tolist():
            leaf = dom.leaves[k]
            if leaf not in dom.own_leaves:
                continue
            last = float(last_by_leaf[k])
            silent = t - last
            parent = dom.taskorg.parent.get(leaf) or leaf
            cands.append(Candidate(t, "unknown-position", self.dom.base.compute_priority("unknown-position"), (leaf,),
                                   f"Unknown position: {dom.name(leaf)} silent for {silent:.0f} s",
                                   key=("unknown-position", leaf), measure=silent, merge_group=("unknown", parent),
                                   details={"unit": leaf, "last_report_t": last, "silent_s": round(silent, 1)}))
