"""The EA's picture of the situation: friendly entity positions and hostile tracks,
and the watchman that keeps it current and filters what reaches the manager."""
from __future__ import annotations

import math
from collections import Counter, defaultdict
from operator import itemgetter

import numpy as np

from ea_agent.core.plan import TaskOrg
from ea_agent.core.adjudication import Adjudicator, Entity, Report
from ea_agent.core.geo import Projection
from .messages import LocationReport, SensorTrack

_first = itemgetter(0)


class Picture:
    """Positions in metres. Entities are rows of numpy arrays; units are index sets."""

    def __init__(self, taskorg: TaskOrg, proj: Projection):
        self.proj = proj
        self.ents = sorted(taskorg.entity_unit)
        self.eidx = {e: i for i, e in enumerate(self.ents)}
        n = len(self.ents)
        self.lon = [math.nan] * n          # last raw report (python lists: fast scalar access)
        self.lat = [math.nan] * n
        self.seen = np.zeros(n)            # scenario time of the last report, changed or not
        self.xy = np.full((n, 2), np.nan)
        self.moved_t = np.full(n, np.nan)  # when xy last changed, and the velocity that change showed
        self.vel = np.zeros((n, 2))
        self.all_known = n == 0            # every entity has a position (xy never goes back to NaN)
        self.ent_leaf = [taskorg.entity_unit[e] for e in self.ents]
        self.tracks: dict[str, Entity] = {}      # the adjudicated picture of hostile entities
        self._live: tuple = (None, [], np.zeros((0, 2)))   # live_tracks() of the `tracks` object first item
        self.adj = Adjudicator()
        self.rebuild(taskorg)

    def rebuild(self, taskorg: TaskOrg) -> None:
        """Member index arrays per unit (after load or a reorganization)."""
        by_leaf: dict[str, list[int]] = defaultdict(list)
        for i, u in enumerate(self.ent_leaf):
            by_leaf[u].append(i)
        self.leaves = sorted(by_leaf)
        li = {u: k for k, u in enumerate(self.leaves)}
        self.ent_leaf_i = np.array([li[u] for u in self.ent_leaf], dtype=np.intp)
        self.leaf_members = {u: np.array(v, dtype=np.intp) for u, v in by_leaf.items()}
        self.members = {u: np.array(sorted(i for leaf in taskorg.subtree(u) for i in by_leaf.get(leaf, ())),
                                    dtype=np.intp) for u in taskorg.units}
        self.units = sorted(taskorg.units)
        # unit x leaf membership: unit centroids are sums over their leaves
        self.unit_leaf = np.zeros((len(self.units), len(self.leaves)))
        for r, u in enumerate(self.units):
            for leaf in taskorg.subtree(u):
                if leaf in li:
                    self.unit_leaf[r, li[leaf]] = 1.0
        # positions(): weighted bincounts whose bins are (leaf, column): per bin the same
        # sequential sums as one bincount per column
        n = len(self.leaves)
        self._bins = (5 * self.ent_leaf_i)[:, None] + np.arange(5, dtype=np.intp)
        self._w = np.empty((len(self.ent_leaf), 5))
        self._w[:, 0] = 1.0
        # member counts once every entity is known: fixed until the next reorganization
        lc = np.bincount(self.ent_leaf_i, minlength=n).astype(float)[:, None]
        uc = self.unit_leaf @ lc
        lc[lc == 0.0] = np.nan
        uc[uc == 0.0] = np.nan
        self._known_counts = (lc, uc)
        # the same sums once every entity is known: x, y bins (2 per leaf) over contiguous
        # (entity, 2) arrays, written next to the fixed counts (strided writes cost more)
        self._bins2 = ((2 * self.ent_leaf_i)[:, None] + np.arange(2, dtype=np.intp)).ravel()
        self._sums = np.empty((n, 5))
        self._sums[:, 0] = np.bincount(self.ent_leaf_i, minlength=n)

    def member_xy(self, unit: str) -> np.ndarray:
        pts = self.xy[self.members[unit]]
        if self.all_known:   # the usual case once every entity has reported: nothing to drop
            return pts
        return pts[~np.isnan(pts[:, 0])]

    def centroid(self, unit: str) -> tuple[float, float] | None:
        pts = self.member_xy(unit)
        if len(pts) == 0:
            return None
        c = pts.mean(axis=0)
        return float(c[0]), float(c[1])

    def swept(self, unit: str, now: float, horizon_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Each member's last reported position and where it is by `now` if it kept its
        last velocity (at most `horizon_s`; none once it reported standing still): the
        true position lies between the two when reports are stale."""
        m = self.members[unit]
        p0 = self.xy[m]
        ok = ~np.isnan(p0[:, 0])
        m, p0 = m[ok], p0[ok]
        seen = self.seen[m]
        moved = self.moved_t[m]
        dt = np.where(seen > moved + 0.5, 0.0, np.clip(now - moved, 0.0, horizon_s))
        return p0, p0 + self.vel[m] * dt[:, None]

    def reckoned(self, now: float, horizon_s: float) -> np.ndarray:
        """Every entity's position dead-reckoned to `now` from its last report and velocity
        (at most `horizon_s`; not at all once it reported standing still)."""
        dt = now - self.moved_t
        np.minimum(dt, horizon_s, out=dt)   # as np.clip (NaN stays NaN), at a third of its cost
        np.maximum(dt, 0.0, out=dt)
        dt[self.seen > self.moved_t + 0.5] = 0.0
        # dt is NaN only for entities never reported, whose position is NaN anyway
        return self.xy + self.vel * dt[:, None]

    def centroids(self, xy: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Centroids of every leaf and every unit (NaN where no member position is known),
        of the last reports or of other member positions `xy` (dead-reckoned)."""
        leaf, unit, _ = self._centroids(self.xy if xy is None else xy, None)
        return leaf, unit

    def positions(self, now: float, horizon_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Leaf centroids of the last reports, and unit centroids (n_units, 4): columns 0:2 of
        the last reports, 2:4 of the members dead-reckoned to `now` (see `reckoned`). One
        vectorised pass with few numpy calls: this runs at nearly every epoch close."""
        xy = self.xy
        dt = now - self.moved_t
        np.minimum(dt, horizon_s, out=dt)    # as np.clip (NaN stays NaN), at a third of its cost
        np.maximum(dt, 0.0, out=dt)
        dt[self.seen > self.moved_t + 0.5] = 0.0
        n = len(self.leaves)
        if self.all_known:
            r = self.vel * dt[:, None]
            r += xy   # = xy + vel * dt, as reckoned() (addition commutes exactly)
            sums = self._sums
            sums[:, 1:3] = np.bincount(self._bins2, weights=xy.ravel(), minlength=2 * n).reshape(n, 2)
            sums[:, 3:5] = np.bincount(self._bins2, weights=r.ravel(), minlength=2 * n).reshape(n, 2)
            u = self.unit_leaf @ sums
            lc, uc = self._known_counts
        else:   # unknown entities dropped: one bincount over (leaf, column) bins of [1, x, y, rx, ry]
            w = self._w
            w[:, 1:3] = xy
            r = w[:, 3:5]
            np.multiply(self.vel, dt[:, None], out=r)
            r += xy
            ok = ~np.isnan(xy[:, 0])
            sums = np.bincount(self._bins[ok].ravel(), weights=w[ok].ravel(), minlength=5 * n)
            sums = sums.astype(float, copy=False).reshape(n, 5)   # int when nothing is known
            u = self.unit_leaf @ sums
            lc, uc = sums[:, :1], u[:, :1]
            lc[lc == 0.0] = np.nan   # no member known: NaN centroids, without a divide warning
            uc[uc == 0.0] = np.nan
        return sums[:, 1:3] / lc, u[:, 1:5] / uc

    def _centroids(self, xy: np.ndarray, rxy: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """bincount per leaf, then one membership matrix product for every unit."""
        n = len(self.leaves)
        if self.all_known and xy is self.xy:   # nothing to drop: no masking copies (same sums, same order)
            li = self.ent_leaf_i
        else:
            ok = ~np.isnan(xy[:, 0])
            li = self.ent_leaf_i[ok]
            xy = xy[ok]
            rxy = rxy[ok] if rxy is not None else None
        sums = np.empty((n, 5 if rxy is not None else 3))
        sums[:, 0] = np.bincount(li, minlength=n)
        sums[:, 1] = np.bincount(li, weights=xy[:, 0], minlength=n)
        sums[:, 2] = np.bincount(li, weights=xy[:, 1], minlength=n)
        if rxy is not None:
            sums[:, 3] = np.bincount(li, weights=rxy[:, 0], minlength=n)
            sums[:, 4] = np.bincount(li, weights=rxy[:, 1], minlength=n)
        u = self.unit_leaf @ sums
        lc, uc = sums[:, :1], u[:, :1]
        lc[lc == 0.0] = np.nan   # no member known: NaN centroids, without a divide warning
        uc[uc == 0.0] = np.nan
        leaf = sums[:, 1:3] / lc
        unit = u[:, 1:3] / uc
        now = u[:, 3:5] / uc if rxy is not None else None
        return leaf, unit, now

    def apply_locations(self, reports: list[LocationReport]) -> set[str]:
        """Project a batch of reports in one pyproj call; returns the leaf units touched."""
        n = len(reports)
        if not n:
            return set()
        eidx = self.eidx
        rows = [(eidx[r.entity], r.lon, r.lat, r.t) for r in reports]   # one pass over the reports
        a = np.array(rows, dtype=float).T.copy()   # contiguous float64 rows: projected in place
        idx = a[0].astype(np.intp)
        self.proj.to_xy_inplace(a[1], a[2])
        new = a[1:3].T                       # (n, 2): x, y
        t = a[3]
        dt = t - self.moved_t[idx]
        ok = (dt > 0) & (dt <= 120.0)        # NaN (first report) compares false
        stale = ~ok
        dt[stale] = 1.0                      # no divide warning; those velocities are zeroed below
        v = (new - self.xy[idx]) / dt[:, None]
        v[stale] = 0.0
        self.vel[idx] = v
        self.moved_t[idx] = t
        self.xy[idx] = new
        if not self.all_known:
            self.all_known = not np.isnan(self.xy[:, 0]).any()
        return set(map(self.ent_leaf.__getitem__, map(_first, rows)))   # the leaves touched (in C)

    def live_tracks(self) -> tuple[list[str], np.ndarray]:
        """The hostile entities with some strength, sorted by id, and their positions (n, 2).
        Asked by several detectors each epoch: kept until `tracks` is replaced (read-only)."""
        tracks = self.tracks
        if self._live[0] is not tracks:
            ids = [k for k in sorted(tracks) if tracks[k].strength > 0]
            xy = np.array([(tracks[k].x, tracks[k].y) for k in ids]).reshape(-1, 2)
            xy.flags.writeable = False
            self._live = (tracks, ids, xy)
        return list(self._live[1]), self._live[2]

    def apply_tracks(self, tracks: list[SensorTrack]) -> set[str]:
        """Track reports go through adjudication; returns the entities whose state changed."""
        if not tracks:
            return set()
        x, y = np.array([t.lon for t in tracks]), np.array([t.lat for t in tracks])
        if x.dtype == np.float64 and y.dtype == np.float64:   # the usual case: fresh arrays, projected in place
            self.proj.to_xy_inplace(x, y)
        else:
            x, y = self.proj.to_xy(x, y)
        kept = False
        for t, tx, ty in zip(tracks, x.tolist(), y.tolist()):   # 1-d arrays (from lists): python floats
            # an air track is no ground threat (contact, envelopes, areas): as gone for this picture
            strength = 0 if t.domain == "air" else t.strength
            vx = vy = 0.0
            if t.at is not None and t.speed and t.heading is not None:   # dead-reckoned: extrapolate it
                h = math.radians(t.heading)
                vx, vy = t.speed * math.sin(h), t.speed * math.cos(h)
            kept |= self.adj.update(Report(t.t, t.source, t.track, float(tx), float(ty), strength, t.lon, t.lat,
                                           vx, vy, t.at))
        if not kept:
            return set()
        return self._picture(max(t.t for t in tracks))

    def advance_tracks(self, now: float) -> set[str]:
        """Dead-reckoned tracks moved on to `now` (each epoch's close): the entities whose
        position changed; nothing when no track has a velocity."""
        return self._picture(now) if self.adj.moving() else set()

    def _picture(self, now: float) -> set[str]:
        new = self.adj.picture(now)
        changed = {k for k, v in new.items() if self.tracks.get(k) != v} | (self.tracks.keys() - new.keys())
        self.tracks = new
        return changed


class Watchman:
    """Filters reports not worth the manager's attention and keeps the picture current.

    A location report that did not move is dropped (its time still counts: the unit
    is not silent). Reports of other units far from ours update the picture but are
    not passed on. A report older than one taken for its entity is stale, dropped.
    Unknown entities raise KeyError, which the manager counts.
    """

    def __init__(self, picture: Picture, cfg: dict):
        self.p = picture
        # the picture's per-entity containers, never replaced: one attribute load less per message
        self.eidx, self.seen, self.lon, self.lat = picture.eidx, picture.seen, picture.lon, picture.lat
        self.eps = float(cfg["watchman"]["unchanged_m"]) / 111_000.0
        self.interest = float(cfg["watchman"]["interest_m"])
        self.own = [False] * len(picture.ents)
        self.bbox = (-math.inf, -math.inf, math.inf, math.inf)
        self.quiet: list[LocationReport] = []
        # plain int counters: a Counter update per message is measurable on the hot path
        self.n_unchanged = self.n_irrelevant = self.n_passed = self.n_stale = 0

    @property
    def stats(self) -> Counter:
        """What the watchman did with the messages it saw."""
        return Counter({k: v for k, v in (("passed", self.n_passed), ("unchanged", self.n_unchanged),
                                          ("irrelevant", self.n_irrelevant), ("stale", self.n_stale)) if v})

    def set_own(self, own_leaves: set[str]) -> None:
        self.own = [u in own_leaves for u in self.p.ent_leaf]

    def set_bbox(self, pts: np.ndarray) -> None:
        """Bounding box of our own units, grown by the interest radius."""
        if len(pts):
            lo, hi = pts.min(axis=0) - self.interest, pts.max(axis=0) + self.interest
            self.bbox = (lo[0], lo[1], hi[0], hi[1])

    def watch(self, msg):
        """Called for every message: plain locals and list lookups, no numpy scalars
        where a python value will do."""
        if type(msg) is LocationReport:
            p = self.p
            i = self.eidx.get(msg.entity)
            if i is None:
                raise KeyError(f"location report for unknown entity {msg.entity!r}")
            lon = msg.lon
            lat = msg.lat
            if not (-180.0 <= lon <= 180.0 and -90.0 <= lat <= 90.0):   # also catches NaN
                raise ValueError(f"location report for {msg.entity}: field 'lat'/'lon' not a valid coordinate "
                                 f"({lat}, {lon})")
            t = msg.t
            seen = self.seen
            if t > seen[i]:
                seen[i] = t
            elif t < seen[i]:   # older than one we took (a peer bringing a place up to date): stale
                self.n_stale += 1
                return None
            eps = self.eps
            plon = self.lon
            plat = self.lat
            if abs(plon[i] - lon) < eps and abs(plat[i] - lat) < eps:
                self.n_unchanged += 1
                return None
            plon[i] = lon
            plat[i] = lat
            if not self.own[i]:
                x, y = p.xy[i].tolist()
                b = self.bbox
                if not (x != x or (b[0] <= x <= b[2] and b[1] <= y <= b[3])):
                    self.quiet.append(msg)
                    self.n_irrelevant += 1
                    return None
            self.n_passed += 1
            return msg
        if type(msg) is SensorTrack:
            tr = self.p.adj.latest.get((msg.source, msg.track))
            if tr is not None and tr.strength == msg.strength and abs(tr.lon - msg.lon) < self.eps \
                    and abs(tr.lat - msg.lat) < self.eps:
                self.n_unchanged += 1
                return None
        self.n_passed += 1
        return msg
