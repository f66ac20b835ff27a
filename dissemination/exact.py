"""The peer's exact interest: a received key tested against its fine key expressions.

Coarse subscriptions (`coarse.py`) let through more than the EA asked for; this is
the cheap test that drops the rest: one compiled pattern per family and a bounded
cache of answers (a unit's key repeats until it moves to another cell)."""
from __future__ import annotations

import re
from collections import defaultdict
from typing import Callable

CACHE_MAX = 50_000


def _pattern(expr: str) -> str:
    out = []
    chunks = expr.split("/")
    for i, c in enumerate(chunks):
        sep = "/" if i else ""
        if c == "**":
            out.append("(?:/.*)?" if i else ".*")   # `a/**` matches `a` too
        elif "*" in c:   # `*` one chunk, `$*` part of one
            out.append(sep + re.escape(c.replace("$*", "\0")).replace("\\*", "[^/]+").replace("\0", "[^/]*")
                       if c != "*" else sep + "[^/]+")
        else:
            out.append(sep + re.escape(c))
    return "".join(out)


def exact(exprs: set[str] | list[str], root: str) -> Callable[[str], bool]:
    """A test of concrete keys under `root` against the fine expressions."""
    n = len(root) + 1
    by_fam: dict[str, list[str]] = defaultdict(list)
    for e in exprs:
        fam = e[n:].split("/", 1)[0] if e.startswith(root + "/") else "*"
        by_fam[fam].append(_pattern(e))
    if any("*" in f for f in by_fam):   # a family wildcard: every key goes through one pattern
        one = re.compile("|".join(f"(?:{p})" for ps in by_fam.values() for p in ps))
        fams = None
    else:
        fams = {f: re.compile("|".join(f"(?:{p})" for p in ps)) for f, ps in by_fam.items()}
    cache: dict[str, bool] = {}

    def match(key: str) -> bool:
        hit = cache.get(key)
        if hit is not None:
            return hit
        if fams is None:
            ok = one.fullmatch(key) is not None
        else:
            pat = fams.get(key[n:].split("/", 1)[0])
            ok = pat is not None and pat.fullmatch(key) is not None
        if len(cache) >= CACHE_MAX:
            cache.clear()
        cache[key] = ok
        return ok
    return match
