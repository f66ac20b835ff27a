"""Zenoh mTLS configuration and access-control rules generated from the scenario.

Every secured process carries the same `access_control` section: each process enforces
on its own links (ingress: what it accepts from the peer whose certificate CN is the
subject), so a forged frame, order, liveliness token or journal reply is dropped by
the receiver itself. Default deny; egress allows everything under the root (reads are
limited on ingress, by who may declare subscribers and queries) except `delete`, which
nobody may send or accept.

Each CN is exactly one subject (a CN in two subjects with different attributes would get
the union of their allows), and keys come from `KeySpace` where it has a method, so the
rules and the keys cannot drift apart.

| subject | ingress allowed, besides reading |
|---|---|
| `ea.<U>` | put alert/<U>/*, bye/<U>, ack/<U>/*, msn/<U>/*, ord/<U>, cmdlog/<U>, notice/*/<U> (its re-notifications and escalations), dir/<U>/confirm (confirmations it infers); queryable + reply dirj/<U>, query dirj/* (directives for late joiners); token alive/<U>/* |
| `observer` | reading alert/** and alive/** only |
| `console` | as observer, plus reading cmdlog/** and notice/**, put cmd/** |
| `tak` | reading as `console.<U>` (cmdlog/** included: acknowledged emergencies end), put cmd/*/ack/* (ATAK users' acknowledgements), its own source src/tak (PLI) |
| `console.<U>` (with a task organization) | put cmd/*/*/<U> (commands sent as U's console: each EA checks U commands it now), dir/<U>/* (U's orders to its subtree, U's confirmations up: saim_mesh/authority/directives.py); reading what an observer reads plus cmdlog/**, notice/**, the sources' frames src/* |

Reading = declare_subscriber, declare_liveliness_subscriber, liveliness_query on `<root>/**`
(observer and console: on alert/** and alive/** only).
"""
from __future__ import annotations

import json
from pathlib import Path

import zenoh

from dissemination.keyspace import KeySpace

from .pki import SecurityError, check_identity

ALL_MESSAGES = ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
                "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"]
READ = ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"]
SENT = [m for m in ALL_MESSAGES if m != "delete"]
READ_ONLY_ROLES = ("observer", "console")


def endpoint_tls(port: int, host: str = "127.0.0.1") -> str:
    """'tls/127.0.0.1:PORT' (the listener's certificate carries SAN IP:127.0.0.1)."""
    return f"tls/{host}:{int(port)}"


def tls_config(pki_dir: str | Path, name: str) -> dict:
    """The `transport/link` part for mutual TLS as NAME: the same certificate for
    listening and connecting (serverAuth + clientAuth), absolute paths, checked first."""
    ca, cert, key = check_identity(pki_dir, name)
    return {"protocols": ["tls"],
            "tls": {"root_ca_certificate": str(ca),
                    "listen_certificate": str(cert), "listen_private_key": str(key),
                    "connect_certificate": str(cert), "connect_private_key": str(key),
                    "enable_mtls": True}}


def _chunk(kind: str, name: str) -> str:
    if not name or any(c in name for c in "/*$#?") or name != name.strip():
        raise SecurityError(f"bad {kind} name {name!r} for a key chunk")
    return name


def identities(units, groups, taskorg=None, routers=()) -> list[str]:
    """Every certificate CN the rules know (one subject each); `console.<U>` per unit
    when the task organization is known (a commander's console acts for U's subtree);
    `router.<R>` per router of the topology."""
    consoles = [f"console.{u}" for u in units] if taskorg is not None else []
    return [*(f"ea.{u}" for u in units), *READ_ONLY_ROLES, "tak",
            *consoles, *(f"router.{r}" for r in routers), *(f"source.{n}" for n in source_names(units, taskorg, groups))]


def source_names(units, taskorg=None, groups=()) -> list[str]:
    """The live sources the rules know (issue 31): `cp.<U>` for each command post, i.e.
    each unit of the mesh, each unit with subordinates and each unit directly under the top
    (the live mesh's sources per command post: saim_mesh/live/up.py), and `fusion.<G>` for
    each sensor group (its fusion node, a live source of tracks beside its sensors)."""
    cps = set(units)
    if taskorg is not None:   # every unit with subordinates, and every unit directly under the top
        cps |= {p for p in taskorg.parent.values() if p}
        cps |= {u for u, p in taskorg.parent.items() if p == taskorg.root}
    return [f"cp.{u}" for u in sorted(cps)] + [f"fusion.{g}" for g in sorted(groups)]


def access_control(root: str, units, groups, taskorg=None, routers=()) -> dict:
    """The full `access_control` section for a mesh under ROOT with an EA per unit of
    UNITS and a fusion node per group of GROUPS (names, or a dict group -> sensors).
    With TASKORG, a `console.<U>` identity per unit may send commands as U's console; the
    EAs take them from U only while U commands them (reorganizations included)."""
    ks = KeySpace(root)
    r = ks.root
    units = sorted(dict.fromkeys(_chunk("unit", u) for u in units))
    groups = sorted(dict.fromkeys(_chunk("fusion group", g) for g in groups))

    rules: list[dict] = []
    subjects: list[dict] = []
    policies: list[dict] = []

    def rule(rid: str, messages: list[str], keys: list[str], flow: str = "ingress") -> str:
        rules.append({"id": rid, "flows": [flow], "permission": "allow", "messages": messages,
                      "key_exprs": keys})
        return rid

    adv = f"{r}/src/**/@adv/**"   # zenoh.ext's verbatim chunks (below), a key group's too: named wherever they flow
    out = rule("egress", SENT, [f"{r}/**", adv], "egress")
    read_all = rule("read", READ, [f"{r}/**"])
    read_public = rule("read_public", READ, [f"{r}/alert/**", f"{r}/alive/**"])
    # live sources (zenoh.ext): the advanced publisher puts on src/<name> and keeps its cache
    # and liveliness token under src/<name>/@adv/...; `@` chunks are verbatim (`**` does not
    # reach them), so they are named. An EA's advanced subscriber queries those caches and
    # declares its own token under src/*/@adv/...
    ea_src = [rule("ea_src_read", READ, [adv]), rule("ea_src", ["query", "liveliness_token"], [adv, f"{r}/src/**"]),
              rule("ea_srcj", ["query"], [ks.srcj("*")])]   # the sources' durable journals

    def subject(cn: str, rule_ids: list[str]) -> None:
        subjects.append({"id": cn, "cert_common_names": [cn]})
        policies.append({"id": f"policy.{cn}", "rules": rule_ids, "subjects": [cn]})

    for u in units:
        subject(f"ea.{u}", [out, read_all, *ea_src,
                            rule(f"ea.{u}.put", ["put"], [f"{r}/alert/{u}/*", ks.bye(u), ks.ack(u, "*"),
                                                          f"{r}/msn/{u}/*", f"{r}/ord/{u}",
                                                          ks.cmdlog(u), ks.notice("*", u),
                                                          f"{r}/dir/{u}/confirm"]),   # its inferred confirmations
                            # directives it took, for late joiners (saim_mesh/authority/directives.py)
                            rule(f"ea.{u}.dirj", ["declare_queryable", "reply"], [f"{r}/dirj/{u}"]),
                            rule(f"ea.{u}.dirq", ["query"], [f"{r}/dirj/*"]),
                            rule(f"ea.{u}.token", ["liveliness_token"], [ks.alive(u, "*")])])
    for n in source_names(units, taskorg, groups):
        mine = [ks.src(n), f"{r}/src/{n}/**", f"{r}/src/{n}/**/@adv/**", ks.srcj(n)]   # its stream or key groups
        # ... and the acks of the EAs that depend on it (live/pace.py: a max-speed source's pace)
        subject(f"source.{n}", [out, rule(f"source.{n}.read", READ, [f"{r}/src/**", adv, ks.ack("*", n)]),
                                rule(f"source.{n}.put", ["put", "declare_queryable", "reply", "liveliness_token"],
                                     mine),
                                rule(f"source.{n}.query", ["query"], [adv])])
    subject("observer", [out, read_public])
    read_cmdlog = rule("read_cmdlog", READ, [ks.cmdlog("**"), f"{r}/notice/**"])
    subject("console", [out, read_public, read_cmdlog, rule("console_put", ["put"], [f"{r}/cmd/**"])])
    read_seen = rule("read_console", READ, [ks.src("*"), f"{r}/src/*/**"])   # the sources' frames, by group too: the picture
    # the TAK gateway: reads what a console reads, but no commands
    subject("tak", [out, read_public, read_seen, read_cmdlog,
                    # ... and acknowledgements from ATAK users, sent as their mapped unit's console
                    # (each EA checks that unit commands it, as for a console: issue 33.6)
                    rule("tak_put", ["put"], [ks.cmd("*", "ack", "*")]),
                    # its PLI are its own source's stream
                    rule("tak_src", ["put", "declare_queryable", "reply", "liveliness_token"],
                         [ks.src("tak"), f"{r}/src/tak/@adv/**", ks.srcj("tak")])])
    if taskorg is not None:
        # the last chunk of a command's key names the console's unit: the certificate holds
        # it to that; the receiving EA decides whether that unit commands it at that moment
        # (its subtree changes with reorganizations, which access control cannot follow)
        for u in units:
            subject(f"console.{u}", [out, read_public, read_cmdlog, read_seen,
                                     rule(f"console.{u}.put", ["put"], [ks.cmd("*", "*", u), f"{r}/dir/{u}/*"])])
    # a router relays what others sent: its link carries every role's traffic, so a
    # receiver behind it sees the router's CN (zenoh-security.md). Each router enforces
    # the rules above on its own ingress, where it still sees the sender's certificate,
    # and authority is signed end to end (security/sign.py).
    if routers:
        # ... the advanced publishers' caches and tokens too (`@adv` chunks are verbatim: not
        # under `**`): without them no recovery query or reply crosses a router link
        relay = rule("router_relay", SENT, [f"{r}/**", adv])
        for name in sorted(dict.fromkeys(_chunk("router", x) for x in routers)):
            subject(f"router.{name}", [out, relay])
    for kind, items in (("rule", rules), ("subject", subjects), ("policy", policies)):
        ids = [x["id"] for x in items]
        if len(ids) != len(set(ids)):
            raise SecurityError(f"duplicate {kind} ids in the access-control rules: {sorted(ids)}")
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def _endpoints(conf: zenoh.Config, path: str) -> list[str]:
    try:
        v = json.loads(conf.get_json(path))
    except Exception:
        return []
    if isinstance(v, dict):   # listen/connect endpoints may be given per mode
        return [e for eps in v.values() if isinstance(eps, list) for e in eps]
    return list(v or [])


def secure_config(conf: zenoh.Config, pki_dir: str | Path, name: str, root: str, units, groups,
                  taskorg=None, routers=()) -> zenoh.Config:
    """Insert mTLS as NAME (certificates checked first: Zenoh's connecting side is silent
    about bad files), `transport/link/protocols: ["tls"]` (else a plain-tcp peer found
    by scouting joins) and the access-control rules into CONF; returns CONF."""
    if name not in identities(units, groups, taskorg, routers):
        raise SecurityError(f"identity {name!r} has no subject in the access-control rules "
                            f"(units: {', '.join(units)}; fusion groups: {', '.join(groups) or 'none'})")
    for path in ("listen/endpoints", "connect/endpoints"):
        plain = [e for e in _endpoints(conf, path) if not str(e).startswith("tls/")]
        if plain:
            raise SecurityError(f"{path}: {', '.join(plain)} not TLS (use endpoint_tls(port))")
    link = tls_config(pki_dir, name)
    acl = access_control(root, units, groups, taskorg, routers)
    conf.insert_json5("transport/link/protocols", json.dumps(link["protocols"]))
    for k, v in link["tls"].items():
        conf.insert_json5(f"transport/link/tls/{k}", json.dumps(v))
    conf.insert_json5("access_control", json.dumps(acl))
    return conf
