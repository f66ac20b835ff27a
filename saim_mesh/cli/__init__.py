"""`saim-mesh` command line: run, evaluate, missions, generate, validate, report (offline.py);
the mesh's processes (mesh up, source, sources, peer, router, topology, tak, link:
mesh.py); certs and deploy (deploy.py); a commander's commands and console (commands.py) and
directives to a subtree (order, plan: directives.py). Each group registers its own
subcommands; every command is a thin layer over the package it drives."""
from __future__ import annotations

import sys

from .. import scenario as S
from . import commands, deploy, directives, mesh, offline
from .args import _fail, _Parser, _seconds, _zenoh_args


def parser() -> _Parser:
    """Every `saim-mesh` command and its flags (docs/cli.md is generated from it)."""
    p = _Parser(prog="saim-mesh", description=__doc__)
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("robots", help="robots that obey their EAs over the mesh: robots team OUT | robot | ea | hub "
                                  "(saim-mesh robots -h)")
    offline.add(sub)
    mesh.add(sub)
    deploy.add(sub)
    commands.add(sub)
    directives.add(sub, _zenoh_args, _seconds)   # order, plan: directives to a subtree (issue 33)
    return p


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else list(argv)
    if args[:1] == ["robots"]:   # the robot team that obeys its EAs has its own subcommands
        from ..robots.cli import main as robots_main
        return robots_main(args[1:])
    a = parser().parse_args(argv)
    from ea_agent.core.config import ConfigError
    try:
        return a.fn(a)
    except BrokenPipeError:
        return 0
    except KeyboardInterrupt:
        print("saim-mesh: interrupted", file=sys.stderr)
        return 130
    except (S.ScenarioError, ConfigError) as err:   # they name file, place and field
        return _fail(err)
    except KeyError as err:   # an unknown unit; str() of a KeyError would quote its message
        return _fail(err.args[0] if err.args else err)
    except ValueError as err:   # from a loader that does not name its file: still one line
        return _fail(f"{type(err).__name__}: {err}")
    except OSError as err:   # a file not found or unreadable (--out, --config, ...)
        return _fail(f"{err.filename}: {err.strerror}" if err.filename and err.strerror else err)


__all__ = ["main", "parser"]
