"""The peer's exact interest: a received key tested against its fine key expressions.

Key-group subscriptions (`streams.py`) let through more than the EA asked for (a group is
coarser than the keys its interest names); this is the cheap test that tells the rest. The fine set changes every re-registration (as
units move), so building the test must cost little too: expressions are indexed by
family, second and third chunk (a place's block and cell), and a key is compared chunk by chunk with
the few that can match it; answers are cached until the next re-registration."""
from __future__ import annotations

from collections import defaultdict
from typing import Callable

CACHE_MAX = 8192   # about twice the keys a brigade EA hears at once (an entity's key changes with its cell): a few MB
ANY = "*"


def _chunks_match(pat: tuple[str, ...], key: list[str], i: int = 0, j: int = 0) -> bool:
    """Zenoh's matching of one concrete key against one expression (`*` one chunk,
    `**` any number of chunks, `$*` part of a chunk)."""
    while i < len(pat):
        p = pat[i]
        if p == "**":
            if i == len(pat) - 1:
                return True
            return any(_chunks_match(pat, key, i + 1, k) for k in range(j, len(key) + 1))
        if j >= len(key):
            return False
        if p != key[j] and p != ANY and not ("$*" in p and _dollar(p, key[j])):
            return False
        i += 1
        j += 1
    return j == len(key)


def _dollar(p: str, chunk: str) -> bool:
    parts = p.split("$*")
    if not chunk.startswith(parts[0]) or not chunk.endswith(parts[-1]) or len(chunk) < len(parts[0]) + len(parts[-1]):
        return False
    pos = len(parts[0])
    for mid in parts[1:-1]:
        k = chunk.find(mid, pos, len(chunk) - len(parts[-1]))
        if k < 0:
            return False
        pos = k + len(mid)
    return True


def exact(exprs: set[str] | list[str], root: str, cache: bool = True) -> Callable[[str], bool]:
    """A test of concrete keys under `root` against the fine expressions (`cache`: remember
    each key's answer; off for a caller that caches what it learns per key itself)."""
    n = len(root) + 1
    exact_keys: set[str] = set()
    by_third: dict[tuple[str, str, str], list[tuple[str, ...]]] = defaultdict(list)   # (family, block, cell)
    by_second: dict[tuple[str, str], list[tuple[str, ...]]] = defaultdict(list)   # (family, chunk 1)
    by_family: dict[str, list[tuple[str, ...]]] = defaultdict(list)               # (family, wildcard chunk 1)
    other: list[tuple[str, ...]] = []                                             # no family under our root
    for e in exprs:
        if "*" not in e:
            exact_keys.add(e)
            continue
        if not e.startswith(root + "/"):
            other.append(tuple(e.split("/")))
            continue
        c = tuple(e[n:].split("/"))
        if "*" in c[0]:
            other.append(tuple(e.split("/")))
        elif len(c) > 2 and "*" not in c[1] and "*" not in c[2]:
            by_third[(c[0], c[1], c[2])].append(c)
        elif len(c) > 1 and "*" not in c[1]:
            by_second[(c[0], c[1])].append(c)
        else:
            by_family[c[0]].append(c)
    answers: dict[str, bool] = {}

    def match(key: str) -> bool:
        hit = answers.get(key)
        if hit is not None:
            return hit
        ok = key in exact_keys
        if not ok and key.startswith(root) and key[n - 1:n] == "/":
            c = key[n:].split("/")
            cands = by_family.get(c[0], ())
            if len(c) > 1:
                cands = [*by_second.get((c[0], c[1]), ()), *cands]
                if len(c) > 2:
                    cands = [*by_third.get((c[0], c[1], c[2]), ()), *cands]
            ok = any(_chunks_match(p, c) for p in cands)
        if not ok and other:
            full = key.split("/")
            ok = any(_chunks_match(p, full) for p in other)
        if cache:
            if len(answers) >= CACHE_MAX:
                answers.clear()
            answers[key] = ok
        return ok
    return match
