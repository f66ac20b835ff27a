"""Key groups of the live mesh: which of a source's streams a data message goes on, and
which streams an EA subscribes to for its interest (docs/keyspace.md, "Key groups").

A data key (`KeySpace.key`) names one message; a group names the stream of a source
that carries it, coarse enough that one source has few streams (a publisher each) and
fine enough that an EA hears little beyond its interest. From the message's template:
the family, then the first placeholder: a place keeps its block (the cell is dropped)
and, when a command path follows it, the path's first `depth` chunks (a company's
subtree: `group_depth`); any other placeholder keeps its one chunk and ends the
group. So, in SUO: positions `pos/<block>/<path to the company>`, tracks `trk/<block>`,
calls for fire `cff/<block>`, confirmations `msn/<unit>`, orders `ord/<issuer>`,
reorganizations `org/<unit>`, fusion input `hit/<group>`; for the robot team states and
sightings `st/<block>`, `sgt/<block>`, agent messages `agm/<to>`.

`subscriptions` maps an EA's interest (the key expressions `Interest.of` computes) to
group expressions: a superset (every key an interest expression matches is in a group
one of them matches), coarser where the interest binds a chunk the group drops (the
requester of a call for fire: every `cff` block). Pure and cached: a source maps each
message, an EA each re-registration."""
from __future__ import annotations

from collections.abc import Iterable

import zenoh

from .keyspace import Template

CACHE_MAX = 8192    # keys remembered (an entity's key repeats until it changes cell)


def group_depth(taskorg) -> int:
    """Command-path chunks per group: a company's subtree whatever sits above it (2 in a
    battalion, BN/A; 3 in a brigade, BDE/1BN/1A): the hierarchy's height less two."""
    height = max((len(taskorg.path(u).split("/")) for u in taskorg.units), default=3)
    return max(1, height - 2)


class _Layout:
    """One template's chunk layout in a concrete key: where its place and path are."""

    def __init__(self, tpl: Template):
        self.family = tpl.family
        chunks: list[str] = []
        for op, a in tpl.ops:
            chunks += ["place", "cell"] if op == "place" else [op]
        self.n = len(chunks)
        self.has_path = "path" in chunks
        self.path_at = chunks.index("path") if self.has_path else -1
        self.after = self.n - self.path_at - 1 if self.has_path else 0   # fixed chunks after the path
        first = next((i for i, c in enumerate(chunks) if c != "lit"), None)
        self.first = first                       # index of the first placeholder chunk (None: none)
        self.kind = chunks[first] if first is not None else "lit"
        # a place followed at once by a path: the group keeps the path too
        self.place_path = self.kind == "place" and self.path_at == (first or 0) + 2


class Streams:
    """Maps data keys under `root` to group chunks, interest expressions to group
    expressions. `templates`: the data messages' key templates (texts or `Template`s);
    `depth`: command-path chunks a group keeps (a group cut from a shorter path is the
    path itself)."""

    def __init__(self, root: str, templates: Iterable, depth: int):
        self.root = root
        self.n = len(root) + 1
        self.depth = max(1, int(depth))
        self.layout: dict[str, _Layout] = {}
        for t in templates:
            tpl = t if isinstance(t, Template) else Template(t)
            self.layout[tpl.family] = _Layout(tpl)
        self._cache: dict[str, str] = {}

    @classmethod
    def of(cls, root: str, taskorg, templates: Iterable) -> "Streams":
        return cls(root, templates, group_depth(taskorg))

    # -- a message's group ---------------------------------------------------------------
    def group(self, key: str) -> str:
        """The group of a concrete data key ('pos/X3Y4/BDE/1BN/1A'), relative to the root.
        A key of an unknown family, or one too short for its template, is its family's
        one group: never an error (the key came from our own `KeySpace.key`)."""
        g = self._cache.get(key)
        if g is None:
            if len(self._cache) >= CACHE_MAX:
                self._cache.clear()
            g = self._cache[key] = self._find(key[self.n:].split("/"))
        return g

    def _find(self, c: list[str]) -> str:
        lay = self.layout.get(c[0])
        if lay is None or lay.first is None or len(c) < lay.n:
            return c[0]
        i = lay.first
        if lay.kind == "place":
            if lay.place_path:
                path = c[lay.path_at:len(c) - lay.after][:self.depth]
                return "/".join([*c[:i + 1], *path])
            return "/".join(c[:i + 1])
        if lay.kind == "path":
            return "/".join([*c[:i], *c[i:len(c) - lay.after][:self.depth]])
        return "/".join(c[:i + 1])

    # -- an interest's groups ------------------------------------------------------------
    def subscriptions(self, exprs: Iterable[str]) -> set[str]:
        """Group expressions (relative to the root) covering every data key the interest
        expressions match. Expressions outside the root or of no data family (the clock)
        need no group."""
        out: set[str] = set()
        for e in exprs:
            if not e.startswith(self.root + "/"):
                continue
            c = e[self.n:].split("/")
            if "*" in c[0]:   # any family: every group
                return {"**"}
            lay = self.layout.get(c[0])
            if lay is None:
                continue   # not a data family (clock, control keys): no stream carries it
            out |= self._expr_groups(lay, c)
        return _drop_included(out)

    def _expr_groups(self, lay: _Layout, c: list[str]) -> set[str]:
        fam = c[0]
        whole = {f"{fam}/**"}
        if lay.first is None:
            return {fam}
        i = lay.first
        if "**" in c[1:i + 1] or len(c) <= i:
            return whole
        head = c[:i]
        if lay.kind == "place":
            block = c[i]
            if not lay.place_path:
                return {"/".join([*head, block])}
            if len(c) <= i + 2 or c[i + 1] == "**":
                return {"/".join([*head, block, "**"])}
            return {"/".join([*head, block, *p]) for p in self._path_exprs(c[i + 2:], lay.after)}
        if lay.kind == "path":
            return {"/".join([*head, *p]) for p in self._path_exprs(c[i:], lay.after)}
        return {"/".join([*head, c[i] if c[i] != "**" else "*"])}

    def _path_exprs(self, rest: list[str], after: int) -> list[list[str]]:
        """Group tails (a path's first `depth` chunks, or wildcards) for the expression
        chunks `rest` that start where the template's path does and end with its `after`
        fixed chunks."""
        d = self.depth
        if "**" not in rest:   # the path's length is known: all chunks but the last `after`
            path = rest[:len(rest) - after] if after else rest
            if not path:
                return [["**"]]
            p = path[:d]
            return [p]   # `*` chunks stay `*`: Zenoh matches them chunk for chunk
        lit: list[str] = []
        for x in rest:
            if "*" in x:
                break
            lit.append(x)
        if not lit:
            return [["**"]]
        out = [lit[:d] if len(lit) >= d else [*lit, "**"]]
        # `**` may match nothing, so the last literal chunks may be the template's fixed
        # chunks after a shorter path (an entity named as a unit): that path's group too.
        # Whatever the task organization (a reorganization makes new paths)
        for k in range(max(1, len(lit) - after), len(lit)):
            out.append(lit[:k][:d])
        return out


def _drop_included(exprs: set[str]) -> set[str]:
    """Without the expressions another one of the set includes (a sample matching two
    subscriptions is delivered twice)."""
    if "**" in exprs or len(exprs) < 2:
        return {"**"} if "**" in exprs else set(exprs)
    ks = {e: zenoh.KeyExpr(e) for e in exprs}
    wide = [e for e in exprs if "*" in e]   # only an expression with a wildcard includes another
    return {e for e in exprs if not any(o != e and ks[o].includes(ks[e]) for o in wide)}


def subscriptions_keyexprs(streams: Streams, exprs: Iterable[str], prefix: str) -> set[str]:
    """`subscriptions` under a stream prefix (`<root>/src/<source>`): the key expressions an
    EA declares for one source."""
    return {f"{prefix}/{g}" for g in streams.subscriptions(exprs)}
