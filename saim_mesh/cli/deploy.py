"""`saim-mesh certs | deploy`: certificates and the mesh across hosts (docs/deployment.md)."""
from __future__ import annotations

import sys
from pathlib import Path

from .. import scenario as S
from .args import _count, _seconds, _fail, _lines, DEFAULT_SCENARIO


def cmd_certs(a) -> int:
    from ea_agent import domains

    from ..security.pki import make_pki, names_for
    if a.deploy:   # each host's addresses and names in its processes' certificates
        from ..deploy import certs
        from ..deploy.check import load
        from ..deploy.file import DeployError
        try:
            dep, sc = load(a.deploy)
        except DeployError as e:
            return _lines(e.lines)
        out = Path(a.out) if a.out else dep.pki
        made = certs.make(dep, sc, out)
        sans = certs.sans_of(dep)
        print(f"{len(made)} identities in {out} (CA: {out / 'ca.pem'}); {sum(1 for n in sans if sans[n])} of them "
              "also name their host's addresses: "
              + "; ".join(f"{h.name} {' '.join((*h.addresses, *h.names)) or '-'}" for h in dep.hosts.values()))
        return 0
    sc = S.load(a.scenario, events=False)
    out = a.out or "out/pki"
    bad = [r for r in a.routers or () if not r.replace("-", "").replace("_", "").isalnum()]
    if bad:
        raise ValueError(f"--routers: {bad[0]!r} is not a router name (letters, digits, - and _)")
    made = make_pki(Path(out), names_for(sc, a.units or domains.of(sc).mesh_units(sc), consoles=True)
                    + [f"router.{r}" for r in a.routers or ()])
    print(f"{len(made)} identities in {out} (CA: {Path(out) / 'ca.pem'}): {', '.join(sorted(made))}")
    return 0


def cmd_deploy(a) -> int:
    """`deploy init SCENARIO`, `deploy FILE --check [--host H]`, `deploy FILE --host H`."""
    from ..deploy.check import load
    from ..deploy.file import DeployError
    if a.file == "init":
        if not a.scenario:
            raise ValueError("deploy init SCENARIO: give the scenario folder")
        from ..deploy import init
        if not 1 <= a.port <= 65535:
            raise ValueError(f"deploy init: --port {a.port} out of range (1-65535)")
        sc = S.load(a.scenario, events=False)
        out = Path(a.out or f"deploy-{sc.name}.toml")
        try:
            dep = init.write(sc, a.scenario, out, addresses=a.addresses, port=a.port, consoles=not a.no_consoles,
                             secure=not a.insecure, pki=a.pki)
        except ValueError as e:   # --addresses
            raise ValueError(f"deploy init: {e}") from None
        print(f"{out}: {len(dep.hosts)} hosts ({', '.join(dep.hosts)}), {len(dep.routers)} routers, "
              f"{len(dep.eas())} EA peers, {len(dep.sources())} sources")
        return 0
    if a.scenario:
        raise ValueError(f"deploy {a.file}: unexpected {a.scenario!r} (deploy FILE --check | --host NAME; "
                         "deploy init SCENARIO)")
    try:
        dep, sc = load(a.file, a.host)
    except DeployError as e:
        return _lines(e.lines, sys.stdout if a.check else None)
    if a.check:
        where = f" host {a.host}: {len(dep.hosts[a.host].eas)} EA peers," if a.host else ""
        print(f"{a.file}: OK: {len(dep.hosts)} hosts, {len(dep.routers)} routers, {len(dep.eas())} EA peers, "
              f"{len(dep.sources())} sources;{where} {'secure' if dep.secure else 'insecure'}")
        return 0
    if not a.host:
        raise ValueError(f"deploy {a.file}: give --host NAME (one of {', '.join(dep.hosts)}) or --check")
    import signal

    from ..deploy.launch import run_host
    from ..security.pki import SecurityError
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))   # stopped: still reap every child (run_host's finally)
    out = Path(a.out_dir or f"out/deploy/{a.host}")
    try:
        res = run_host(dep, sc, a.host, out, show=not a.quiet, timeout=a.timeout, until_done=a.exit_when_done,
                       console_linger=a.console_linger, max_restarts=a.restarts, fresh=a.fresh or None)
    except (SecurityError, RuntimeError, TimeoutError) as e:   # a child that would not start: one line
        return _fail(e)
    except KeyboardInterrupt:
        return 130
    return 0 if len(res["peers"]) == len(res["units"]) or not a.exit_when_done else 1


def add(sub) -> None:
    """Register certs and deploy on `sub`."""
    ce = sub.add_parser("certs", help="make a test CA and a certificate per identity of a scenario's mesh")
    ce.add_argument("scenario", nargs="?", default=str(DEFAULT_SCENARIO))
    ce.add_argument("--out", default=None, help="where the certificates go (default out/pki; with --deploy: "
                    "the file's pki)")
    ce.add_argument("--units", nargs="+", metavar="UNIT", help="EA identities (default: battalion, companies, platoons)")
    ce.add_argument("--routers", nargs="+", metavar="NAME", help="also a router.NAME identity for each (a mesh "
                    "launched by hand: `saim-mesh router --name NAME`)")
    ce.add_argument("--deploy", metavar="TOML", help="a deployment file: the scenario is the file's, and each host's "
                    "addresses and names go into its processes' certificates")
    ce.set_defaults(fn=cmd_certs)

    de = sub.add_parser("deploy", help="the mesh across hosts: deploy init SCENARIO | deploy FILE --check | "
                                       "deploy FILE --host NAME (docs/deployment.md)")
    de.add_argument("file", metavar="FILE|init", help="a deployment file (TOML), or init to write one")
    de.add_argument("scenario", nargs="?", help="init: the scenario folder")
    de.add_argument("--check", action="store_true",
                    help="say what is wrong with the file, one line each (exit 2), and start nothing; with --host, "
                         "also whether this machine is that host")
    de.add_argument("--host", metavar="NAME", help="run this host's routers, EAs, sources, consoles, TAK gateway")
    de.add_argument("--out-dir", help="alerts, logs, state (default out/deploy/HOST)")
    de.add_argument("--exit-when-done", action="store_true",
                    help="stop once this host's EA peers are done (by default the host runs until stopped: other "
                         "hosts may still need its routers and sources)")
    de.add_argument("--timeout", type=_seconds, default=None, metavar="S", help="stop after S seconds")
    de.add_argument("--quiet", action="store_true", help="do not print alerts as they come")
    de.add_argument("--fresh", action="store_true",
                    help="a clean start: delete the EAs' logs and journals and the sources' state an earlier run left "
                         "in --out-dir (default: a restart keeps them when they are this deployment's)")
    de.add_argument("--restarts", type=_count, default=10, metavar="N",
                    help="restart each of the host's processes that dies up to N times (default 10), then give up "
                         "on it with one line and go on without it (0: never restart)")
    de.add_argument("--console-linger", type=_seconds, default=300.0, metavar="S",
                    help="seconds a console stays up after the scenario's end")
    de.add_argument("--out", metavar="TOML", help="init: the file to write (default deploy-<scenario>.toml)")
    de.add_argument("--addresses", metavar="NET|ADDR[,ADDR...]",
                    help="init: one address per host from a network (198.18.0.0/24: .1, .2, ...), a list, or one "
                         "address for all (ports then differ; default 127.0.0.1: this machine)")
    de.add_argument("--port", type=int, default=7447, help="init: the routers' port (default 7447)")
    de.add_argument("--no-consoles", action="store_true", help="init: no commander's console per host")
    de.add_argument("--insecure", action="store_true", help="init: secure = false (no mTLS, no access control)")
    de.add_argument("--pki", metavar="DIR", help="init: where the certificates will be (default pki/ beside the file)")
    de.set_defaults(fn=cmd_deploy)
