"""The Zenoh key space (docs/keyspace.md): one key per message, chosen so that a
peer can subscribe by mission, geography (grid cells) and command (its subtree).

Data keys come from each message class's `KEY` template (the domain owns its
messages and says where they go); this module builds and parses every key from
them, and owns the control keys. Placeholders: `{place}` (two chunks, block/cell,
from the message's lon/lat), `{path:F}` (the command path of the unit field F
names, any depth), `{group:F}` (the fusion group of sensor F), `{F}` (field F).
SUO's families:

  <root>/pos/<block>/<cell>/<command path>/<entity>    friendly positions
  <root>/trk/<block>/<cell>/<track>                    hostile tracks (fused)
  <root>/hit/<fusion group>/<sensor>           raw sensor hits, to the group's fusion source
  <root>/msn/<unit>/<mission>                  mission start/end confirmations
  <root>/ord/<unit>                            orders to a unit (and its subordinates)
  <root>/cff/<block>/<cell>/<requester>/<cff>  calls for fire and confirmations
  <root>/org/<unit>                            reorganizations
  <root>/alert/<owner>/<type>                  alerts raised by an EA
  <root>/alive/<unit>/<peer>                   liveliness tokens (presence)
  <root>/rtr/<router>/<zid>                    a router's liveliness token (a link or router lost)
  <root>/bye/<unit>                            a peer leaving cleanly (not an alarm)
  <root>/ack/<unit>/<source>                   how far unit's EA has taken in a source it depends on (its pace)
  <root>/src/<source>, <root>/srcj/<source>    a live source's frames and its journal (queryable)
  <root>/cmd/<unit>/<kind>/<by>                a command to a unit's EA from the console of unit <by>
  <root>/cmdlog/<unit>                         the EA's answer to every command (CmdResult)
UV (robot team): <root>/st/<block>/<cell>/<robot>, <root>/sgt/<block>/<cell>/<robot>/<target>,
<root>/agm/<to>/<sender> (docs/uv-domain.md).
"""
from __future__ import annotations

import math
import re
from collections.abc import Iterable

import zenoh

CELL_M = 2000.0
BLOCK = 4   # cells per block side: a block chunk groups 4 x 4 cells (8 km with 2 km cells)
_PH = re.compile(r"^\{(\w+)(?::(\w+))?\}$")


def cell(x: float, y: float, size: float = CELL_M) -> str:
    """Grid cell chunk of a projected position, e.g. 'x268y1950'."""
    return f"x{math.floor(x / size)}y{math.floor(y / size)}"


def block_of(c: str) -> str:
    """The block chunk holding a cell chunk: 'x268y1950' -> 'X67Y487'."""
    i, j = c[1:].split("y")
    return f"X{int(i) // BLOCK}Y{int(j) // BLOCK}"


def place(x: float, y: float, size: float = CELL_M) -> str:
    """'<block>/<cell>': two key chunks, so that peers subscribe per cell or per block."""
    c = cell(x, y, size)
    return f"{block_of(c)}/{c}"


def cells_within(x: float, y: float, r: float, size: float = CELL_M) -> set[str]:
    out = set()
    for i in range(math.floor((x - r) / size), math.floor((x + r) / size) + 1):
        for j in range(math.floor((y - r) / size), math.floor((y + r) / size) + 1):
            out.add(f"x{i}y{j}")
    return out


def cells_of_bounds(b: tuple[float, float, float, float], size: float = CELL_M) -> set[str]:
    return {f"x{i}y{j}" for i in range(math.floor(b[0] / size), math.floor(b[2] / size) + 1)
            for j in range(math.floor(b[1] / size), math.floor(b[3] / size) + 1)}


def command_path(taskorg, unit: str) -> str:
    return taskorg.path(unit)


class Template:
    """One message class's key template, split into chunk operations: ("lit", text),
    ("place", ""), ("path", field) (any number of chunks), ("group", field), ("field", name)."""

    def __init__(self, text: str):
        self.text = text
        self.ops: list[tuple[str, str]] = []
        for chunk in text.split("/"):
            m = _PH.match(chunk)
            if m is None:
                if "{" in chunk or not chunk:
                    raise ValueError(f"bad key template {text!r}")
                self.ops.append(("lit", chunk))
            elif m.group(1) in ("place",):
                self.ops.append(("place", ""))
            elif m.group(1) in ("path", "group"):
                self.ops.append((m.group(1), m.group(2) or ""))
            else:
                self.ops.append(("field", m.group(1)))
        if not self.ops or self.ops[0][0] != "lit":
            raise ValueError(f"key template {text!r} must start with its family name")
        if sum(op == "path" for op, _ in self.ops) > 1:
            raise ValueError(f"key template {text!r} has two variable-depth placeholders")
        self.family = self.ops[0][1]
        self.names = {a if op == "field" else op for op, a in self.ops if op != "lit"}
        self._checks: tuple[int, list[tuple[int, str]]] | None = None

    def field_checks(self) -> tuple[int, list[tuple[int, str]]]:
        """What `KeySpace.mismatch` checks: the key's chunk count (negative: at least that
        many, a path being any depth) and (chunk index, field) pairs, counted from the
        end after a path."""
        if self._checks is None:
            ops: list[tuple[str, str]] = []
            for op, a in self.ops:   # a place is two chunks
                ops += [("any", ""), ("any", "")] if op == "place" else [(op, a)]
            var = next((i for i, (op, _) in enumerate(ops) if op == "path"), None)
            if var is None:
                self._checks = len(ops), [(i, a) for i, (op, a) in enumerate(ops) if op == "field"]
            else:
                left, right = ops[:var], ops[var + 1:]
                self._checks = (-(len(left) + len(right) + 1),
                                [(i, a) for i, (op, a) in enumerate(left) if op == "field"]
                                + [(i - len(right), a) for i, (op, a) in enumerate(right) if op == "field"])
        return self._checks

    def expr(self, bind: dict[str, str]) -> str:
        """A key expression selecting this template's keys with the placeholders in
        `bind` fixed (others are wildcards); everything after a path is `**`, unless a
        field after it is fixed (`pos/*/*/**/<entity>`: one entity, wherever it is)."""
        out = []
        for i, (op, a) in enumerate(self.ops):
            if op == "lit":
                out.append(a)
            elif op == "place":
                out.append(bind.get("place", "*/*"))
            elif op == "path":
                out.append(f"{bind['path']}/**" if "path" in bind else "**")
                if not any(o == "field" and b in bind for o, b in self.ops[i + 1:]):
                    break
                out += [bind.get(b, "*") if o == "field" else "*" for o, b in self.ops[i + 1:]]
                break
            else:
                out.append(bind.get(a if op == "field" else op, "*"))
        return "/".join(out)


_TEMPLATES: dict[type, Template] = {}


def template(cls: type) -> Template:
    t = _TEMPLATES.get(cls)
    if t is None:
        text = getattr(cls, "KEY", None)
        if text is None:
            raise ValueError(f"no key for {cls.__name__}")
        t = _TEMPLATES[cls] = Template(text)
    return t


def field_mismatch(checks: Iterable[tuple[str, str]], msg) -> str | None:
    """The first of `KeySpace.key_checks`' (field, chunk) pairs that `msg` breaks, said."""
    for a, c in checks:
        if c != getattr(msg, a):
            return f"field '{a}' {str(getattr(msg, a))[:40]!r} differs from the key's {c[:40]!r}"
    return None


class KeySpace:
    def __init__(self, root: str, sensor_group: dict[str, str] | None = None, cell_m: float = CELL_M):
        if not root or any(c in root for c in "#?*$") or root.startswith("/") or "//" in root:
            raise ValueError(f"bad key-expression root {root!r}")
        if not (isinstance(cell_m, (int, float)) and math.isfinite(cell_m) and cell_m > 0):
            raise ValueError(f"bad grid cell size {cell_m!r}")
        self.root = root
        self.sensor_group = sensor_group or {}   # sensor id -> fusion group
        self.cell_m = float(cell_m)

    @classmethod
    def of(cls, sc, root: str) -> "KeySpace":
        """The key space of a scenario: its fusion groups and grid cell size (scenario.json)."""
        groups = sc.meta.get("fusion", {}).get("groups", {})
        cell_m = sc.meta.get("keyspace", {}).get("cell_m", CELL_M)
        return cls(root, {sid: g for g, sids in groups.items() for sid in sids}, cell_m)

    def place(self, x: float, y: float) -> str:
        return place(x, y, self.cell_m)

    def key(self, msg, taskorg, proj, xy: tuple[float, float] | None = None) -> str:
        """The key of one message; `xy` (its projected position) saves a pyproj call."""
        out = [self.root]
        for op, a in template(type(msg)).ops:
            if op == "lit":
                out.append(a)
            elif op == "field":
                out.append(getattr(msg, a))
            elif op == "place":
                if xy is None:
                    xy = proj.to_xy(msg.lon, msg.lat)
                out.append(place(xy[0], xy[1], self.cell_m))
            elif op == "path":
                v = getattr(msg, a)
                unit = v if v in taskorg.units else taskorg.entity_unit.get(v, "unknown")
                out.append(taskorg.path(unit) if unit in taskorg.units else "unknown")
            else:   # group
                out.append(self.sensor_group.get(getattr(msg, a), "ungrouped"))
        return "/".join(out)

    def mismatch(self, key: str, msg) -> str | None:
        """Why a message does not belong on the key it came on (None when it does).
        Access control says who may publish on a key; this says that what they
        published is what the key claims (an order on ord/A2 is issued by A2)."""
        checks = self.key_checks(key, type(msg))
        return checks if type(checks) is str else field_mismatch(checks, msg)

    def key_checks(self, key: str, cls: type) -> tuple[tuple[str, str], ...] | str:
        """What a message of `cls` on `key` must carry: (field, the key's chunk) pairs,
        or why no such message belongs there. Depends on the key and class alone, so a
        receiver can work it out once per key."""
        n = len(self.root) + 1
        if key[:n] != self.root + "/":
            return f"key {key[:80]!r} outside the root"
        chunks = key[n:].split("/")
        tpl = _TEMPLATES.get(cls) or template(cls)
        if chunks[0] != tpl.family:
            return f"a {cls.KIND} message on {chunks[0]}/ keys"
        count, checks = tpl.field_checks()
        if count > 0 and len(chunks) != count:
            return f"key {key[:80]!r} has {len(chunks)} chunks, not {count}"
        if count < 0 and len(chunks) < -count:
            return f"key {key[:80]!r} has too few chunks"
        return tuple((a, chunks[i]) for i, a in checks)

    def data(self, cls: type, **bind: str) -> str:
        """A key expression for messages of `cls` with some placeholders fixed."""
        return f"{self.root}/{template(cls).expr(bind)}"

    def family(self, key: str) -> str:
        """The family chunk of a key under our root ('pos', 'alert', 'src', ...)."""
        return key[len(self.root) + 1:].split("/", 1)[0]

    def last(self, key: str, n: int = 1) -> list[str]:
        """The last `n` chunks of a key (the unit and peer of alive/ack keys, ...)."""
        return key.rsplit("/", n)[1:]

    def alive(self, unit: str, peer: str = "*") -> str:
        return f"{self.root}/alive/{unit}/{peer}"

    def router(self, name: str, zid: str = "*") -> str:
        """A router's liveliness token: its DELETE on the far side means the router or the link to it is gone."""
        return f"{self.root}/rtr/{name}/{zid}"

    def ack(self, unit: str, peer: str = "*") -> str:
        return f"{self.root}/ack/{unit}/{peer}"


    def bye(self, unit: str) -> str:
        return f"{self.root}/bye/{unit}"

    def cmd(self, unit: str, kind: str = "*", by: str = "*") -> str:
        """Commands to `unit`'s EA (ack, silence, unsilence, set, confirm, cff) from the
        console of unit `by`: access control binds `by` to the sender's certificate, and
        the EA checks that `by` commands it in the hierarchy as it is now."""
        return f"{self.root}/cmd/{unit}/{kind}/{by}"

    def notice(self, to: str = "*", owner: str = "*") -> str:
        """Re-notifications (to = owner) and escalations (to = the owner's superior) of
        `owner`'s EA: not alerts (docs/console.md, "Notifications")."""
        return f"{self.root}/notice/{to}/{owner}"

    def src(self, source: str = "*") -> str:
        """A live source's stream of frames (issue 31): its reports and watermarks, in order
        (`saim_mesh/live`). One key per source: `zenoh.ext`'s advanced publisher keeps
        per-source order, a cache for recovery and late joiners, and miss detection."""
        return f"{self.root}/src/{source}"

    def srcj(self, source: str = "*") -> str:
        """A live source's durable journal, served for catch-up beyond its publisher's cache."""
        return f"{self.root}/srcj/{source}"

    def cmdlog(self, unit: str = "*") -> str:
        """`unit`'s EA answers every command here."""
        return f"{self.root}/cmdlog/{unit}"


def matcher(exprs: list[str]):
    """A fast test of concrete keys against key expressions: the `prefix/**` and
    `prefix/*` forms our subscriptions use are string checks; others go to Zenoh, those
    ending in a literal chunk (`pos/*/*/**/<entity>`, one entity wherever it is) only
    for keys ending in it . An expression Zenoh will not
    parse (`$*`, `a//b`: attacker input in a query) is a ValueError naming it, never a
    `zenoh.ZError` out of the caller's loop."""
    deep, one, other = [], [], []
    by_last: dict[str, list] = {}

    def kexpr(e: str):
        try:
            return zenoh.KeyExpr(e)
        except Exception as err:   # zenoh.ZError is no ValueError
            raise ValueError(f"key expression {e[:80]!r}: {str(err).split(' at /', 1)[0][:160]}") from None
    for e in exprs:
        head = e[:-3] if e.endswith("/**") else e[:-2] if e.endswith("/*") else None
        last = e.rsplit("/", 1)[-1]
        if head is not None and "*" not in head:
            (deep if e.endswith("/**") else one).append(head + "/")
        elif "*" not in last and "$" not in last:
            by_last.setdefault(last, []).append(kexpr(e))
        else:
            other.append(kexpr(e))
    deep_t, one_t = tuple(deep), tuple(one)

    def match(k: str) -> bool:
        if deep_t and k.startswith(deep_t):
            return True
        if one_t and k.startswith(one_t) and any(k.startswith(h) and "/" not in k[len(h):] for h in one_t):
            return True
        if by_last and (xs := by_last.get(k[k.rfind("/") + 1:])):
            kx = zenoh.KeyExpr(k)
            if any(kx.intersects(x) for x in xs):
                return True
        return bool(other) and any(zenoh.KeyExpr(k).intersects(x) for x in other)
    return match
