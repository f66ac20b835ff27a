"""What a peer knows about a received key, worked out once per key: the batch group it
belongs to, whether its EA wants it, and what the key says about a message on it.

An entity's key repeats in every report until it changes cell, so the receive path
pays one dict lookup per report instead of a group walk, an interest test and a
template check each with its own cache and its own copy of the key. Whether the EA
wants a key changes at every re-registration: `reset` marks every key's answer stale.
The keys of cells an entity has left are dead: `sweep`, once a minute of scenario
time, forgets the keys not heard since the sweep before (a brigade EA that wants every
position never re-registers, and would otherwise hold every key it ever heard).
"""
from __future__ import annotations

from typing import Callable

from dissemination.groups import Groups
from dissemination.keyspace import KeySpace

MAX_KEYS = 8192   # about twice the keys a brigade EA hears at once (an entity's key changes with its cell)


class Facts:
    """One key's facts. For messages of class `cls` (the first that came on it): the
    fields in `attrs` must equal the key's chunks in `values`; or `attrs` is None and
    `values` says why no such message belongs on the key. (Two flat slots, not a tuple
    of pairs: a brigade EA keeps ~4k of these.)"""
    __slots__ = ("group", "wanted", "gen", "seen", "cls", "attrs", "values")

    def __init__(self, group: str | None, wanted: bool, gen: int, seen: int):
        self.group, self.wanted, self.gen, self.seen = group, wanted, gen, seen
        self.cls: type | None = None
        self.attrs: tuple[str, ...] | None = ()
        self.values: tuple[str, ...] | str = ()


class KeyFacts(dict):
    """key -> `Facts`. On the hot path: `f = get(key)`, and `learn(key)` when that is None
    or of an older interest (`f.gen != gen`); then `f.seen = epoch`."""

    def __init__(self, ks: KeySpace, groups: Groups, want: Callable[[str], bool], max_keys: int = MAX_KEYS):
        super().__init__()
        self.ks, self.groups, self.want, self.max_keys = ks, groups, want, max_keys
        self.gen = 0   # the interest's generation: a fact of an older one has a stale `wanted`
        self.epoch = 0   # sweeps so far: a fact whose `seen` is older than the last one is dead
        self._shared: dict = {}   # one copy of each group key and attrs tuple, for all the keys that have it
        self._values: dict = {}   # one copy of each key's checked chunks: an entity's keys in every cell share it

    def reset(self, want: Callable[[str], bool]) -> None:
        """A new interest: each key's `wanted` is asked again when the key next comes
        (its group and checks stay: they depend on the key alone)."""
        self.want = want
        self.gen += 1

    def sweep(self) -> int:
        """Forget the keys not heard since the last sweep (an entity reports about every
        30 s; a key it still uses is heard again well within a minute). Returns how many."""
        dead = [k for k, f in self.items() if f.seen < self.epoch]
        for k in dead:
            del self[k]
        self.epoch += 1
        self._values = {f.values: f.values for f in self.values() if type(f.values) is tuple}   # the live ones
        return len(dead)

    def of(self, key: str) -> Facts:
        """The facts of `key`, learned or brought up to date (the hot path inlines this)."""
        f = self.get(key)
        if f is None or f.gen != self.gen:
            return self.learn(key)
        f.seen = self.epoch
        return f

    def learn(self, key: str) -> Facts:
        f = self.get(key)
        if f is not None:   # known under an older interest
            f.wanted, f.gen, f.seen = self.want(key), self.gen, self.epoch
            return f
        if len(self) >= self.max_keys:   # keys of cells left long ago: start over
            self.clear()
            self._values.clear()
        g = self.groups.find(key)
        f = self[key] = Facts(g if g is None else self._shared.setdefault(g, g), self.want(key), self.gen,
                              self.epoch)
        return f

    def checks(self, f: Facts, key: str, cls: type) -> tuple[tuple[str, ...] | None, tuple[str, ...] | str]:
        """(fields, the key's chunks they must equal) for a message of `cls` on `key`,
        or (None, why no such message belongs there)."""
        if f.cls is cls:
            return f.attrs, f.values
        c = self.ks.key_checks(key, cls)
        if type(c) is str:
            attrs, values = None, c
        else:
            a = tuple(x for x, _ in c)
            v = tuple(x for _, x in c)
            attrs, values = self._shared.setdefault(a, a), self._values.setdefault(v, v)
        if f.cls is None:
            f.cls, f.attrs, f.values = cls, attrs, values
        return attrs, values
