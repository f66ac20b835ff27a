"""A deep copy of an EA's state that keeps going on its own: a rebuilt EA restarts from the
copy taken when a source was lost, not from event time 0 (saim_mesh/live/peer.py).

`copy.deepcopy` shares functions, so a timer's closure in the copy would still act on the
original's detectors; here closures are copied with their cells. Objects that are not state
(the scenario, the peer that owns the EA) are shared, never copied."""
from __future__ import annotations

import copy
import threading
import types
from typing import Any, Iterable, TypeVar

T = TypeVar("T")
_lock = threading.Lock()   # the copy module's dispatch is patched for the copy's duration


def _function(f: types.FunctionType, memo: dict) -> types.FunctionType:
    if not f.__closure__:
        return f
    cells = []
    for c in f.__closure__:
        try:
            v = c.cell_contents
        except ValueError:   # a cell not yet filled
            cells.append(types.CellType())
            continue
        cells.append(types.CellType(copy.deepcopy(v, memo)))
    g = types.FunctionType(f.__code__, f.__globals__, f.__name__, f.__defaults__, tuple(cells))
    g.__kwdefaults__, g.__qualname__ = f.__kwdefaults__, f.__qualname__
    g.__dict__.update(f.__dict__)
    memo[id(f)] = g
    return g


def snapshot(obj: T, share: Iterable[Any] = ()) -> T:
    """`obj` copied deeply, closures included, `share`d objects referenced as they are.
    Raises TypeError for state that cannot be copied (a lock, a socket): no snapshot then."""
    memo: dict[int, Any] = {id(s): s for s in share}
    with _lock:
        dispatch = copy._deepcopy_dispatch   # type: ignore[attr-defined]
        before = dispatch[types.FunctionType]
        dispatch[types.FunctionType] = _function
        try:
            return copy.deepcopy(obj, memo)
        finally:
            dispatch[types.FunctionType] = before
