"""saim-mesh's public Python API: publish facts into the mesh, follow alerts, command an EA.

Each object is a context manager holding one Zenoh session (in the style of the
zenoh-python examples); secure when given a PKI folder (`saim-mesh certs`):

    from saim_mesh.api import Source, Alerts, Commander

    with Source("scenarios/small", "cp.A", connect=["tcp/127.0.0.1:7447"]) as src:
        src.report("A2S1E01", -116.6, 35.2, t=12.0)   # an entity's position at event time 12 s
        src.watermark(14.0)                           # nothing at or before 14 s will follow

    with Alerts("scenarios/small", connect=[...], units=["A2"], priorities=["flash"]) as alerts:
        for a in alerts:                              # typed `Alert`s, checked like every payload
            print(a.t, a.type, a.message)

    with Commander("scenarios/small", "A2", connect=[...]) as cdr:
        print(cdr.ack("A2/1"))                       # the EA's answer: {"ok": True, "t": ..., ...}

On a mesh that `saim-mesh mesh up` or `saim-mesh deploy` started (secure, EAs behind
routers), give its output folder instead of endpoints: `mesh="out/mesh"` reads the routers'
endpoints and names (`topology.json`), the key root and the PKI (`host.json`, `pki/`) there:

    with Alerts("scenarios/small", mesh="out/mesh", units=["A2"]) as alerts: ...

Or say it all: `connect=[router endpoint], routers=["hub"], pki="out/mesh/pki", root=...`.
What keeps one from joining (no router reachable, a folder that is no mesh's, missing or
bad certificates) is a `MeshError`: one line saying what and where.

docs/api.md says more; examples/ has one runnable script per idea."""
from __future__ import annotations

import json
import queue
from pathlib import Path
from typing import Iterator

import zenoh

from dissemination.keyspace import KeySpace

from .authority import commands as C
from .protocol import messages as M
from . import scenario as S
from .protocol import gate as G
from .protocol import wire as W
from .live.source import LiveSource
from .launch.zenoh_config import config

__all__ = ["Source", "Alerts", "Commander", "Alert", "LocationReport", "MeshError"]
Alert = M.Alert
LocationReport = M.LocationReport


CONNECT_S = 5.0   # how long a session tries its endpoints before `MeshError`


class MeshError(ConnectionError):
    """This object cannot join the mesh; the message says why in one line."""


def _scenario(sc) -> S.Scenario:
    return sc if not isinstance(sc, (str, Path)) else S.load(sc, events=False)


def _mesh(out, sc, near: str | None) -> dict:
    """What `mesh up` / `deploy` wrote in their output folder `out` for those who join:
    the routers' endpoints (the router of unit `near` first, the others to fall back on),
    their names (trusted as relays), the key root and the PKI folder (None: insecure)."""
    from .net.topology import TopologyError, read_resolved
    out = Path(out)
    if not (out / "topology.json").exists():
        raise MeshError(f"{out}: no topology.json: not the output folder of a running `saim-mesh mesh up` "
                        f"or `deploy` (its --out-dir)")
    try:
        topo, eps = read_resolved(out / "topology.json")
    except TopologyError as e:
        raise MeshError(str(e)) from None
    try:
        state = json.loads((out / "host.json").read_text())
        dep = state["deployment"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise MeshError(f"{out}/host.json: unreadable ({type(e).__name__}): not a mesh's output folder") from None
    if dep.get("scenario") != sc.name:
        raise MeshError(f"{out} runs scenario {dep.get('scenario')!r}, not {sc.name!r}")
    first = topo.router_of(near, sc.taskorg) if near in sc.taskorg.units else topo.top
    first = first if first in eps else sorted(eps)[0]
    pki = state.get("pki") or (str(out / "pki") if (out / "pki").is_dir() else None)
    secure = any(e.startswith("tls/") for e in eps.values())
    return {"connect": [eps[first], *(eps[n] for n in sorted(eps) if n != first)], "routers": sorted(eps),
            "root": dep.get("root"), "pki": pki if secure else None, "secure": secure}


class _Session:
    """One Zenoh session as `identity` (secure with `pki`), opened on __enter__. With
    `routers` (the names of the routers it connects to) a client of them, trusting what
    they relay; `mesh` (an output folder of `mesh up` or `deploy`) gives connect, routers,
    root and pki where not given. `near`: the unit whose router it tries first."""

    def __init__(self, scenario, identity: str, connect=None, listen=None, root=None, pki=None, routers=None,
                 mesh=None, near: str | None = None):
        self.sc = _scenario(scenario)
        self.identity = identity
        if mesh is not None:
            m = _mesh(mesh, self.sc, near)
            connect = connect if connect is not None else m["connect"]
            routers = routers if routers is not None else m["routers"]
            root = root or m["root"]
            pki = pki if pki is not None else m["pki"]
            if m["secure"] and pki is None:
                raise MeshError(f"{mesh} is a secure mesh (tls endpoints) but has no pki/ folder: give pki=DIR")
        self.root = root or f"saim/{self.sc.name}"
        self.ks = KeySpace.of(self.sc, self.root)
        self.connect = list(connect or ())
        from .security.pki import SecurityError
        try:
            self.conf = config(listen if listen is not None else ([] if connect else None), connect, None, False,
                               pki, identity, self.sc, self.root, mode="client" if routers else None,
                               routers=list(routers or ()))
        except SecurityError as e:
            raise MeshError(f"{identity}: {e}") from None
        if self.connect:   # nobody there: say so, rather than retry forever in silence
            self.conf.insert_json5("connect/timeout_ms", str(int(CONNECT_S * 1000)))
            self.conf.insert_json5("connect/exit_on_failure", "true")
        self.session = None

    def __enter__(self):
        try:
            self.session = zenoh.open(self.conf)
        except zenoh.ZError as e:
            why = str(e).split(" at /", 1)[0].strip()
            why = "nobody answered, or refused this identity" if why.startswith("Unable to connect") else why
            raise MeshError(f"{self.identity}: cannot connect to {' '.join(self.connect) or 'the mesh'} within "
                            f"{CONNECT_S:g} s ({why}): is the mesh up, and are these its certificates?") from None
        try:
            self._opened()
        except BaseException:
            self.session.close()
            self.session = None
            raise
        return self

    def _opened(self) -> None:
        pass

    def _closing(self) -> None:
        pass

    def __exit__(self, *exc) -> None:
        try:
            self._closing()
        finally:
            self.session.close()
            self.session = None

class Source(_Session):
    """A source of facts (a unit's reporter, a command post): its own stream of reports and
    watermarks (`saim_mesh.live`). Event times must increase past each watermark given.
    Secure (`pki`): identity `source.<name>`, which the access-control rules know for the
    command posts' sources `cp.<UNIT>` (`security.acl.source_names`). On leaving, it stays
    `linger_s`, and as long as its journal (`state_dir`) was asked within `linger_s`, at
    most `linger_max_s` in all. `by_group`: published by key group (each EA hears only the
    groups of its interest: docs/keyspace.md, "Key groups")."""

    def __init__(self, scenario, name: str, connect=None, listen=None, root=None, pki=None, state_dir=None,
                 routers=None, mesh=None, linger_s: float = 1.0, linger_max_s: float = 30.0, by_group: bool = False):
        super().__init__(scenario, f"source.{name}", connect, listen, root, pki, routers, mesh,
                         near=name.removeprefix("cp."))
        if not (linger_s >= 0 and linger_max_s >= 0):   # also refuses NaN
            raise ValueError(f"Source {name}: linger_s and linger_max_s must be seconds >= 0, "
                             f"not {linger_s!r}, {linger_max_s!r}")
        self.name, self.state_dir, self.src = name, state_dir, None
        self.linger_s, self.linger_max_s = float(linger_s), float(linger_max_s)
        self.by_group = by_group

    def _opened(self) -> None:
        groups = None
        if self.by_group:
            from .live.groupframes import grouper
            groups = grouper(self.sc, self.ks.root)
        self.src = LiveSource(self.session, self.ks, self.name, self.state_dir, groups=groups)

    def put(self, msg: M.Message) -> None:
        """Any data message (a LocationReport, a MissionConfirm, ...)."""
        self.src.put(msg)

    def report(self, entity: str, lon: float, lat: float, t: float) -> None:
        """An entity's position at event time `t` (seconds)."""
        if entity not in self.sc.taskorg.entity_unit:
            raise KeyError(f"unknown entity {entity!r}: not in the task organization of {self.sc.name}")
        self.src.put(M.LocationReport(float(t), entity, float(lon), float(lat)))

    def watermark(self, t: float) -> None:
        """Promise that nothing at or before `t` will follow from this source."""
        self.src.watermark(float(t))

    def _closing(self) -> None:
        self.src.close(end=True)   # the end of the stream: the EAs need not wait for it
        # An EA still catching up (behind, or back after a cut) asks the journal: stay while
        # it asks, or it is left with a gap nobody can fill.
        self.src.linger(self.linger_s, self.linger_max_s)
        self.src.stop()


class Alerts(_Session):
    """Alerts as the EAs publish them, filtered by owner unit, type and priority; iterate
    (blocks), or `get(timeout)`. A payload that is not a valid alert is counted, never raised."""

    def __init__(self, scenario, connect=None, units=None, types=None, priorities=None, root=None, pki=None,
                 identity: str = "observer", routers=None, mesh=None):
        one = sorted(units)[0] if units and len(set(units)) == 1 else None   # its router first
        super().__init__(scenario, identity, connect, None, root, pki, routers, mesh, near=one)
        self.units, self.types = set(units or ()), set(types or ())
        self.priorities = set(priorities or ())
        self.gate = G.Gate(W.T_LIMIT)
        self.q: queue.SimpleQueue = queue.SimpleQueue()

    def _opened(self) -> None:
        keys = [f"{self.root}/alert/{u}/**" for u in sorted(self.units)] or [f"{self.root}/alert/**"]
        self.subs = [self.session.declare_subscriber(k, lambda s: self.q.put((str(s.key_expr),
                                                                              s.payload.to_bytes())))
                     for k in keys]

    def _closing(self) -> None:
        for s in self.subs:
            s.undeclare()

    def get(self, timeout: float | None = None) -> M.Alert | None:
        """The next matching alert, or None after `timeout` seconds."""
        while True:
            try:
                key, payload = self.q.get(timeout=timeout)
            except queue.Empty:
                return None
            a = self.gate.data(payload, key)
            if type(a) is not M.Alert or self.ks.mismatch(key, a) is not None:
                continue
            if self.types and a.type not in self.types or self.priorities and a.priority not in self.priorities:
                continue
            return a

    def __iter__(self) -> Iterator[M.Alert]:
        while True:
            a = self.get()
            if a is not None:
                yield a


class Commander(_Session):
    """The commander of `unit` (identity `console.<unit>`): commands to the EAs of the units
    it commands. Each call returns the EA's answer as a dict (`ok`, `error`, `t`, `ref`)."""

    def __init__(self, scenario, unit: str, connect=None, root=None, pki=None, timeout: float = 10.0,
                 routers=None, mesh=None):
        sc = _scenario(scenario)
        if unit not in sc.taskorg.units:
            raise KeyError(f"unknown unit {unit!r}: not in the task organization of {sc.name}")
        super().__init__(sc, f"console.{unit}", connect, None, root, pki, routers, mesh, near=unit)
        self.unit, self.timeout = unit, timeout

    def _opened(self) -> None:
        from .security.pki import SecurityError
        from .security.sign import signer_for
        try:
            self.signer = signer_for(self.conf)
        except SecurityError as e:
            raise MeshError(f"{self.identity}: {e}") from None

    def send(self, kind: str, to: str | None = None, **fields) -> dict:
        """Any command (`commands.make` checks it; ValueError naming the field) to unit `to`'s EA."""
        cmd = C.make(kind, **fields)
        res = C.send(self.session, self.ks, to or self.unit, cmd, self.unit, self.timeout, self.signer)
        return C.to_dict(res)

    def ack(self, alert: str) -> dict:
        return self.send("ack", alert.rsplit("/", 1)[0], alert=alert)

    def silence(self, id: str, until_t: float, types=(), subjects=(), areas=(), comment: str = "",
                to: str | None = None) -> dict:
        return self.send("silence", to, id=id, until_t=until_t, types=list(types), subjects=list(subjects),
                         areas=list(areas), comment=comment)

    def set(self, key: str, value, to: str | None = None) -> dict:
        return self.send("set", to, key=key, value=value)

    def confirm(self, mission: str, phase: str, to: str | None = None) -> dict:
        return self.send("confirm", to, mission=mission, phase=phase)

    def decide(self, alert: str, option: str) -> dict:
        return self.send("decide", alert.rsplit("/", 1)[0], alert=alert, option=option)

    def inhibit(self, id: str, source: dict, target: dict, equal=("subjects",), for_s: float = 0.0,
                to: str | None = None) -> dict:
        return self.send("inhibit", to, id=id, source=W.MatcherSpec(**source), target=W.MatcherSpec(**target),
                         equal=list(equal), for_s=for_s)

    # -- directives: authority over the mesh (saim_mesh/authority/directives.py) ------------------
    def order(self, action: str, at: float, plan: str = "", mission: str = "", expect=(),
              wait_s: float | None = None) -> dict[str, dict]:
        """Order `unit`'s subtree (execute-plan PLAN, abort-plan, start-mission or
        end-mission MISSION), taking effect at event time `at` in every EA it concerns.
        Returns each EA's answer by unit: those in `expect` (waited for up to `wait_s`,
        default the timeout), and any other that answered meanwhile."""
        return self._direct("order", expect, wait_s, at=at, action=action, plan=plan, mission=mission)

    def reorganize(self, unit: str, new_parent: str, at: float, expect=(), wait_s: float | None = None
                   ) -> dict[str, dict]:
        """Put `unit` (a subordinate of this commander) under `new_parent` (in its subtree)
        from event time `at`: every EA takes it, so all agree on the chain of command."""
        return self._direct("reorganize", expect, wait_s, at=at, unit=unit, new_parent=new_parent)

    def decision(self, alert: str, mission: str, option: str, at: float, expect=(),
                 wait_s: float | None = None) -> dict[str, dict]:
        """Decide on an alert that asked for a decision (`option`: abort, continue or
        branch:<id>) for the whole subtree: every EA of it that runs `mission` carries it
        out at event time `at` (`decide` above tells the alert's own EA only)."""
        return self._direct("decide", expect, wait_s, at=at, alert=alert, mission=mission, option=option)

    def confirm_up(self, mission: str, phase: str, at: float, expect=(), wait_s: float | None = None
                   ) -> dict[str, dict]:
        """Confirm that `unit`'s mission started or ended, at event time `at`: its own EA and
        its superiors' EAs take it (the paper's confirmation from a subordinate EA)."""
        return self._direct("confirm", expect, wait_s, at=at, mission=mission, phase=phase)

    def _direct(self, kind: str, expect, wait_s: float | None, **fields) -> dict[str, dict]:
        import time
        from .authority import directives as D
        D.make(kind, req="check", n=1, **fields)   # a bad directive: ValueError before anything is declared
        key = D.key(self.ks.root, self.unit, kind)
        answers: queue.SimpleQueue = queue.SimpleQueue()
        gate = G.Gate(W.T_LIMIT)
        sub = self.session.declare_subscriber(self.ks.cmdlog("*"),
                                              lambda smp: answers.put((str(smp.key_expr), smp.payload.to_bytes())))
        pub = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        got: dict[str, dict] = {}
        try:
            if not C._wait_matching(pub, time.monotonic() + self.timeout):
                raise TimeoutError(f"no EA of the mesh listening for {kind} directives within "
                                   f"{self.timeout:.0f} s (nothing sent)")
            d = D.publish(self.session, self.ks.root, self.signer, self.unit, kind, pub=pub, **fields)
            end = time.monotonic() + (self.timeout if wait_s is None else wait_s)   # for the answers
            want = set(expect)
            while (left := end - time.monotonic()) > 0 and not (want and want <= set(got)):
                try:
                    k, payload = answers.get(timeout=left)
                except queue.Empty:
                    break
                res = gate.control(W.CmdResult, payload, k)
                if res is not None and res.req == d.req:
                    got[k.rsplit("/", 1)[-1]] = C.to_dict(res)
            return got
        finally:
            pub.undeclare()
            sub.undeclare()


    def publish_plan(self, name: str, version: int, missions: list[dict], at: float, expect=(),
                     wait_s: float | None = None) -> dict[str, dict]:
        """A new plan version for `unit`'s subtree (missions as a plan file lists them):
        every EA of the subtree validates it and executes it at `at` as `<name>.v<version>`."""
        import json
        return self._direct("plan", expect, wait_s, at=at, name=name, version=version,
                            missions=json.dumps(missions).encode())
