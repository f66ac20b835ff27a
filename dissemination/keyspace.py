"""The Zenoh key space (docs/keyspace.md): one key per message, chosen so that a
peer can subscribe by mission, geography (grid cells) and command (its subtree).

  <root>/pos/<block>/<cell>/<command path>/<entity>    friendly positions
  <root>/trk/<block>/<cell>/<track>                    hostile tracks (fused)
  <root>/hit/<fusion group>/<sensor>           raw sensor hits, to the group's fusion node
  <root>/fusion-tick/<group>                   a fusion node's tracks up to clock time t are out
  <root>/msn/<unit>/<mission>                  mission start/end confirmations
  <root>/ord/<unit>                            orders to a unit (and its subordinates)
  <root>/cff/<block>/<cell>/<requester>/<cff>  calls for fire and confirmations
  <root>/org/<unit>                            reorganizations
  <root>/clock                                 scenario-time ticks (ordering barrier)
  <root>/alert/<owner>/<type>                  alerts raised by an EA
  <root>/alive/<unit>/<peer>                   liveliness tokens (presence)
  <root>/bye/<unit>                            a peer leaving cleanly (not an alarm)
  <root>/ack/<unit>/<peer>                     the last clock tick a peer processed (replay pacing)
  <root>/health/<unit>                         a peer's reject counts (its superior alerts on a flood)
  <root>/store/log                             the situation store (queryable)
  <root>/store/fusion/<group>                  a fusion node's published tracks (queryable)
"""
from __future__ import annotations

import math

import zenoh

from saim_mesh import messages as M

CELL_M = 2000.0
BLOCK = 4   # cells per block side: a block chunk groups 4 x 4 cells (8 km)


def cell(x: float, y: float, size: float = CELL_M) -> str:
    """Grid cell chunk of a projected position, e.g. 'x268y1950'."""
    return f"x{math.floor(x / size)}y{math.floor(y / size)}"


def block_of(c: str) -> str:
    """The block chunk holding a cell chunk: 'x268y1950' -> 'X67Y487'."""
    i, j = c[1:].split("y")
    return f"X{int(i) // BLOCK}Y{int(j) // BLOCK}"


def place(x: float, y: float) -> str:
    """'<block>/<cell>': two key chunks, so that peers subscribe per cell or per block."""
    c = cell(x, y)
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
    return "/".join(reversed([unit, *taskorg.ancestors(unit)]))


class KeySpace:
    def __init__(self, root: str, sensor_group: dict[str, str] | None = None):
        if not root or any(c in root for c in "#?*$") or root.startswith("/") or "//" in root:
            raise ValueError(f"bad key-expression root {root!r}")
        self.root = root
        self.sensor_group = sensor_group or {}   # sensor id -> fusion group

    def key(self, msg, taskorg, proj, xy: tuple[float, float] | None = None) -> str:
        """The key of one message; `xy` (its projected position) saves a pyproj call."""
        r = self.root
        k = type(msg)
        if xy is None and hasattr(msg, "lon") and k is not M.Alert:
            xy = proj.to_xy(msg.lon, msg.lat)
        if k is M.LocationReport:
            unit = taskorg.entity_unit.get(msg.entity, "unknown")
            path = command_path(taskorg, unit) if unit in taskorg.units else "unknown"
            return f"{r}/pos/{place(*xy)}/{path}/{msg.entity}"
        if k is M.SensorTrack:
            return f"{r}/trk/{place(*xy)}/{msg.track}"
        if k is M.SensorHit:
            return f"{r}/hit/{self.sensor_group.get(msg.sensor, 'ungrouped')}/{msg.sensor}"
        if k is M.MissionConfirm:
            return f"{r}/msn/{msg.unit}/{msg.mission}"
        if k is M.Order:
            return f"{r}/ord/{msg.issuer}"
        if k is M.CallForFire or k is M.CallForFireConfirm:
            return f"{r}/cff/{place(*xy)}/{msg.requester}/{msg.cff}"
        if k is M.Reorganization:
            return f"{r}/org/{msg.unit}"
        if k is M.Alert:
            return f"{r}/alert/{msg.owner}/{msg.type}"
        raise ValueError(f"no key for {k.__name__}")

    _CLAIMS = {  # key family -> message kinds it carries, and which chunks must equal which fields
        "pos": ({"location"}, ((-1, "entity"),)),
        "trk": ({"track"}, ((-1, "track"),)),
        "hit": ({"hit"}, ((-1, "sensor"),)),
        "msn": ({"mission"}, ((1, "unit"), (2, "mission"))),
        "ord": ({"order"}, ((1, "issuer"),)),
        "cff": ({"cff", "cff-confirm"}, ((-2, "requester"), (-1, "cff"))),
        "org": ({"reorg"}, ((1, "unit"),)),
        "alert": ({"alert"}, ((1, "owner"), (2, "type"))),
    }

    def mismatch(self, key: str, msg) -> str | None:
        """Why a message does not belong on the key it came on (None when it does).
        Access control says who may publish on a key; this says that what they
        published is what the key claims (an order on ord/A2 is issued by A2)."""
        n = len(self.root) + 1
        if key[:n] != self.root + "/":
            return f"key {key[:80]!r} outside the root"
        chunks = key[n:].split("/")
        rule = self._CLAIMS.get(chunks[0])
        if rule is None or msg.KIND not in rule[0]:
            return f"a {msg.KIND} message on {chunks[0]}/ keys"
        for i, fname in rule[1]:
            if not -len(chunks) < i < len(chunks):
                return f"key {key[:80]!r} has too few chunks"
            if chunks[i] != getattr(msg, fname):
                return f"field '{fname}' {str(getattr(msg, fname))[:40]!r} differs from the key's {chunks[i][:40]!r}"
        return None

    def clock(self) -> str:
        return f"{self.root}/clock"

    def alive(self, unit: str, peer: str = "*") -> str:
        return f"{self.root}/alive/{unit}/{peer}"

    def fusion_store(self, group: str) -> str:
        return f"{self.root}/store/fusion/{group}"

    def fusion_tick(self, group: str) -> str:
        return f"{self.root}/fusion-tick/{group}"

    def ack(self, unit: str, peer: str = "*") -> str:
        return f"{self.root}/ack/{unit}/{peer}"

    def health(self, unit: str) -> str:
        return f"{self.root}/health/{unit}"

    def bye(self, unit: str) -> str:
        return f"{self.root}/bye/{unit}"

    def store(self) -> str:
        return f"{self.root}/store/log"


def matcher(exprs: list[str]):
    """A fast test of concrete keys against key expressions: the `prefix/**` and
    `prefix/*` forms our subscriptions use are string checks; others go to Zenoh."""
    deep, one, other = [], [], []
    for e in exprs:
        head = e[:-3] if e.endswith("/**") else e[:-2] if e.endswith("/*") else None
        if head is not None and "*" not in head:
            (deep if e.endswith("/**") else one).append(head + "/")
        else:
            other.append(zenoh.KeyExpr(e))
    deep_t, one_t = tuple(deep), tuple(one)

    def match(k: str) -> bool:
        if deep_t and k.startswith(deep_t):
            return True
        if one_t and k.startswith(one_t) and any(k.startswith(h) and "/" not in k[len(h):] for h in one_t):
            return True
        return bool(other) and any(zenoh.KeyExpr(k).intersects(x) for x in other)
    return match
