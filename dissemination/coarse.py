"""Few, non-overlapping Zenoh subscriptions covering a peer's fine interest.

Zenoh matches every received sample against each subscription of the session (about
0.3 us per subscription here) and delivers a sample once per matching subscription.
So the peer declares coarse key expressions that never overlap (per family and
block, a command subtree's batch group, or a whole low-rate family) and filters
each received key exactly against its fine interest (`exact.py`). Still specific
enough for routers: a company's positions are asked for by block and by group,
never as `pos/**`, unless the peer's subtree is everyone.
"""
from __future__ import annotations

from collections import defaultdict

import zenoh

from .groups import BATCH_CHUNK, Groups

SINGLE_FAMILY_MAX = 8   # more fine expressions than this on a low-rate family: take it whole


def coarse(fine: set[str], root: str, groups: Groups, paths: list[str]) -> set[str]:
    """Coarse key expressions for the fine ones. `paths` are the command paths of every
    unit (the tree that group keys are cut from)."""
    n = len(root) + 1
    by_fam: dict[str, list[list[str]]] = defaultdict(list)
    out: set[str] = set()
    for e in fine:
        if not e.startswith(root + "/"):
            out.add(e)
            continue
        chunks = e[n:].split("/")
        by_fam[chunks[0]].append(chunks)
    depth = groups.depth
    tree = _tree(paths, depth)
    for fam, exprs in by_fam.items():
        lay = groups.layout.get(fam)
        if lay is not None:
            out |= _batched(root, fam, exprs, lay[0] >= 0, tree, depth)
        else:
            out |= _single(root, fam, exprs, fam in groups.placed)
    return _drop_included(out)


def _batched(root: str, fam: str, exprs: list[list[str]], has_path: bool, tree: dict, depth: int) -> set[str]:
    base = f"{root}/{fam}"
    blocks: set[str] = set()
    covered: set[tuple[str, ...]] = set()
    for c in exprs:
        if c[1:] in ([], ["**"]):
            return {f"{base}/*/{BATCH_CHUNK}/**"}
        if c[1] != "*":
            blocks.add(c[1])
            continue
        rest = c[3:] if len(c) > 2 and c[2] == "*" else []
        if rest and rest[-1] == "**":
            rest = rest[:-1]
        if not has_path or not rest or "*" in "".join(rest):
            return {f"{base}/*/{BATCH_CHUNK}/**"}
        covered.add(tuple(rest[:depth]))
    out = set()
    for g in covered:
        g_expr = "/".join(g)
        out.add(f"{base}/*/{BATCH_CHUNK}/{g_expr}" + ("/**" if len(g) < depth else ""))
    for b in sorted(blocks):
        head = f"{base}/{b}/{BATCH_CHUNK}"
        if not has_path:
            out.add(head)
        elif not covered:
            out.add(f"{head}/**")
        else:
            out |= {f"{head}/{x}" for x in _complement(tree, covered, (), depth)}
    return out


def _tree(paths: list[str], depth: int) -> dict[tuple[str, ...], set[str]]:
    """Children of every group node (tuples of at most `depth` chunks); () holds the roots."""
    kids: dict[tuple[str, ...], set[str]] = defaultdict(set)
    for p in [*paths, "unknown"]:
        chunks = tuple(p.split("/")[:depth])
        for i in range(len(chunks)):
            kids[chunks[:i]].add(chunks[i])
    return kids


def _complement(tree, covered: set[tuple[str, ...]], node: tuple[str, ...], depth: int) -> list[str]:
    """Key-expression tails selecting every group under `node` outside the covered subtrees."""
    out = []
    for child in sorted(tree.get(node, ())):
        n = node + (child,)
        if n in covered:
            continue
        if any(c[:len(n)] == n for c in covered):
            out.append("/".join(n))          # the node's own group (entities attached to it)
            out += _complement(tree, covered, n, depth)
        else:
            out.append("/".join(n) + ("/**" if len(n) < depth else ""))
    return out


def _single(root: str, fam: str, exprs: list[list[str]], placed: bool) -> set[str]:
    """A low-rate family (orders, missions, tracks, calls for fire): per block when
    every expression names one, else whole when there are many."""
    full = {f"{root}/{'/'.join(c)}" for c in exprs}
    if len(full) <= 1:
        return full
    if placed and all(len(c) > 2 and c[1] != "*" for c in exprs):   # place-keyed: one per block
        return {f"{root}/{fam}/{c[1]}/**" for c in exprs}
    if len(full) <= SINGLE_FAMILY_MAX and not _overlap(sorted(full)):
        return full
    return {f"{root}/{fam}/**"}


def _overlap(exprs: list[str]) -> bool:
    ks = [zenoh.KeyExpr(e) for e in exprs]
    return any(a.intersects(b) for i, a in enumerate(ks) for b in ks[i + 1:])


def _drop_included(exprs: set[str]) -> set[str]:
    ks = {e: zenoh.KeyExpr(e) for e in exprs}
    return {e for e in exprs if not any(o != e and ks[o].includes(ks[e]) for o in exprs)}


def overlapping(exprs: set[str]) -> list[tuple[str, str]]:
    """Pairs of expressions that intersect (a sample on both would be delivered twice)."""
    es = sorted(exprs)
    ks = [zenoh.KeyExpr(e) for e in es]
    return [(es[i], es[j]) for i in range(len(es)) for j in range(i + 1, len(es)) if ks[i].intersects(ks[j])]
