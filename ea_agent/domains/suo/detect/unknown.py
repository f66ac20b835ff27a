"""Unknown position: own units silent for longer than the VOI threshold, looked
for on the periodic scan (silence is the absence of messages, so no change
would ever trigger it)."""
from __future__ import annotations

import numpy as np

from ea_agent.core.alert import Candidate

from .base import Changes, Detector


class UnknownPositions(Detector):
    TYPES = {"unknown-position": "reporting-requirement"}

    # (ent_leaf_i it was built for, entities by leaf, each leaf's first, every leaf has one)
    _order: tuple = (None, None, None, False)

    def _last_by_leaf(self) -> np.ndarray:
        """Each leaf's last report time (0 if later than none): entities sorted by leaf once per
        task organization, then one reduceat (np.maximum.at is slow per element)."""
        pic = self.dom.pic
        leaf_i = pic.ent_leaf_i
        n = len(self.dom.leaves)
        if self._order[0] is not leaf_i or len(self._order[2]) != n:
            order = np.argsort(leaf_i, kind="stable")
            starts = np.searchsorted(leaf_i[order], np.arange(n))
            fast = n > 0 and bool((np.diff(starts) > 0).all()) and int(starts[-1]) < len(order)
            self._order = (leaf_i, order, starts, fast)
        _, order, starts, fast = self._order
        if not fast:   # a leaf without entities (leaves are made from entities: never)
            last = np.zeros(n)
            np.maximum.at(last, leaf_i, np.array(pic.seen))
            return last
        return np.maximum(np.maximum.reduceat(pic.seen[order], starts), 0.0)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        if not ch.rescan:
            return
        dom = self.dom
        thr = float(dom.voi_cfg["unknown_position_s"])
        last_by_leaf = self._last_by_leaf()
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
