"""Key groups: what one batch message carries, and where it is published.

Reports of a batched family (positions, robot states) are many and small; the replay
sends those of one group and clock tick as one message, on the group's key:

  <root>/<family>/<block>/_b/<first GROUP_DEPTH chunks of the command path>

(`_b` stands where a cell chunk would: no cell is named so). Families without a
command path group by block only (`<root>/st/<block>/_b`). A group is coarse enough
that a tick's reports of a company in one 8 km block travel together, and specific
enough that routers keep a battalion's positions at home.
"""
from __future__ import annotations

from .keyspace import Template

BATCH_CHUNK = "_b"
GROUP_DEPTH = 2            # command-path chunks in a group key: BN/A (a company's subtree) in a battalion
CACHE_MAX = 8192   # about twice the keys a brigade EA hears at once (an entity's key changes with its cell): a few MB
BATCHED = frozenset({"pos", "st"})   # families the replay batches; hits and authority messages stay single


def _layout(tpl: Template) -> tuple[int, int] | None:
    """(index of the path's first chunk, chunks after it) in a concrete key of a batched
    template with a command path; (-1, 0) without a path; None when not batchable."""
    if tpl.family not in BATCHED or "place" not in tpl.names:
        return None
    chunks: list[str] = []
    for op, _ in tpl.ops:
        chunks += ["", ""] if op == "place" else [op]
    if "path" not in chunks:
        return -1, 0
    i = chunks.index("path")
    return i, len(chunks) - i - 1


def group_depth(taskorg) -> int:
    """Command-path chunks per group: a company's subtree whatever sits above it (2 in a
    battalion, BN/A; 3 in a brigade, BDE/1BN/1A): the hierarchy's height less two."""
    height = max((len(taskorg.path(u).split("/")) for u in taskorg.units), default=3)
    return max(1, height - 2)


class Groups:
    """Maps a concrete data key (under `root`) to its group key, or None when single."""

    def __init__(self, root: str, templates: dict[str, Template], depth: int = GROUP_DEPTH):
        self.root = root
        self.depth = depth
        self.n = len(root) + 1
        self.layout = {fam: lay for fam, tpl in templates.items() if (lay := _layout(tpl)) is not None}
        self.placed = frozenset(fam for fam, tpl in templates.items() if "place" in tpl.names)
        self._cache: dict[str, str | None] = {}   # an entity's key repeats until it changes cell

    def group(self, key: str) -> str | None:
        g = self._cache.get(key, False)
        if g is False:
            if len(self._cache) >= CACHE_MAX:
                self._cache.clear()
            g = self._cache[key] = self.find(key)
        return g

    def find(self, key: str) -> str | None:
        """`group` without the cache (for a caller that caches what it learns per key itself)."""
        chunks = key[self.n:].split("/")
        lay = self.layout.get(chunks[0])
        if lay is None or len(chunks) < 3:
            return None
        head = f"{self.root}/{chunks[0]}/{chunks[1]}/{BATCH_CHUNK}"
        i, after = lay
        if i < 0:
            return head
        path = chunks[i:len(chunks) - after][:self.depth]
        return f"{head}/{'/'.join(path)}" if path else None

    def is_batch(self, key: str) -> bool:
        chunks = key[self.n:].split("/", 3)
        return len(chunks) >= 3 and chunks[2] == BATCH_CHUNK and chunks[0] in self.layout
