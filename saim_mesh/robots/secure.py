"""Mutual TLS and access control for the robots' closed loop, as an addition to the mesh's
rules (`security/acl.access_control`), built here so that the shared rules need not
change before they are folded in (docs/uv-domain.md names the rules to add there).

Added to the mesh's rules, for each robot R of the task organization:
- `robot.R` (its controller): publish its reports as the live source R (put, queryable,
  reply, token on src/R and src/R/@adv/**); read and recover its EA's task stream
  (subscribe, query, token on task/R and task/R/@adv/**); nothing else;
- `ea.R`: publish R's task stream (put, queryable, reply, token on task/R,
  task/R/@adv/**);
- every EA: query and token on the robots' sources (the mesh's rules give that already);
- a router relays task/*/@adv/** too (`@` chunks are verbatim: `**` does not reach them).
"""
from __future__ import annotations

import json
from pathlib import Path

import zenoh

from dissemination.keyspace import KeySpace

from ..security.acl import READ, SENT, access_control, tls_config
from ..security.pki import make_pki

ROUTER = "hub"


def identities(units: list[str], robots: list[str]) -> list[str]:
    return [*(f"ea.{u}" for u in units), *(f"robot.{r}" for r in robots), f"router.{ROUTER}"]


def make(pki_dir: Path, units: list[str], robots: list[str], extra=()) -> None:
    """Certificates (127.0.0.1) and signing keys for every process of the loop."""
    make_pki(pki_dir, [*identities(units, robots), *extra])


def acl(root: str, taskorg, robots: list[str]) -> dict:
    units = sorted(taskorg.units)
    base = access_control(root, units, [], taskorg, routers=[ROUTER])
    rules, subjects, policies = base["rules"], base["subjects"], base["policies"]
    r = KeySpace(root).root

    def rule(rid: str, messages: list[str], keys: list[str], flow: str = "ingress") -> str:
        rules.append({"id": rid, "flows": [flow], "permission": "allow", "messages": messages, "key_exprs": keys})
        return rid
    task_adv = f"{r}/task/*/@adv/**"
    out = rule("robots_egress", SENT, [f"{r}/**", f"{r}/src/*/@adv/**", task_adv], "egress")
    for rid in robots:
        mine = [f"{r}/task/{rid}", f"{r}/task/{rid}/@adv/**"]
        src = [f"{r}/src/{rid}", f"{r}/src/{rid}/@adv/**"]
        ids = [out, rule(f"robot.{rid}.put", ["put", "declare_queryable", "reply", "liveliness_token"], src),
               rule(f"robot.{rid}.tasks", [*READ, "query", "liveliness_token"], mine)]
        subjects.append({"id": f"robot.{rid}", "cert_common_names": [f"robot.{rid}"]})
        policies.append({"id": f"policy.robot.{rid}", "rules": ids, "subjects": [f"robot.{rid}"]})
        pol = next(p for p in policies if p["id"] == f"policy.ea.{rid}")
        pol["rules"] += [out, rule(f"ea.{rid}.tasks", ["put", "declare_queryable", "reply", "liveliness_token"],
                                   mine)]
    for pol in policies:   # every EA reads the task streams' advanced-publisher chunks (tokens it sees)
        if pol["id"].startswith("policy.ea.") or pol["id"] == f"policy.router.{ROUTER}":
            extra = rule(f"{pol['id']}.task_adv", [*READ, "query", "liveliness_token", "put", "reply",
                                                   "declare_queryable"] if "router" in pol["id"] else READ,
                         [task_adv])
            pol["rules"] += [out, extra]
    return base


def config(pki_dir: Path, name: str, root: str, taskorg, robots: list[str], connect: list[str] | None = None,
           listen: list[str] | None = None) -> zenoh.Config:
    """A secure session config as `name`: mTLS, our access-control rules, no scouting."""
    from ..launch.zenoh_config import config as zc
    conf = zc(listen=listen, connect=connect, mode="router" if listen else "client")
    link = tls_config(pki_dir, name)
    conf.insert_json5("transport/link/protocols", json.dumps(link["protocols"]))
    for k, v in link["tls"].items():
        conf.insert_json5(f"transport/link/tls/{k}", json.dumps(v))
    conf.insert_json5("access_control", json.dumps(acl(root, taskorg, robots)))
    return conf
