"""Plan versions over the mesh (issue 33, item 3): a commander publishes a new plan for
its subtree (a `plan` directive: a name, a version and the missions as JSON), and each EA
it concerns validates it exactly as a plan file is validated (the domain's own loader,
against the scenario's task organization and overlay) before switching to it at the
stated event time. A bad plan is refused with the validator's message; the old one stays."""
from __future__ import annotations

import hashlib
import json
import tempfile
from pathlib import Path
from typing import Callable

from ea_agent.core.scenario import ScenarioError

MAX_PLAN_BYTES = 48 * 1024   # the missions' JSON (a battalion's whole plan is ~20 kB)
_CACHE: dict[tuple, object] = {}


def validator(sc) -> Callable[[str, bytes], object]:
    """`validate(name, body) -> PlanSpec` for `sc`'s domain; ValueError with the
    validator's message when the plan is bad."""
    from ea_agent import domains
    dom = domains.of(sc)
    if getattr(dom, "NAME", "") != "suo":
        def refuse(name: str, body: bytes):
            raise ValueError(f"plan versions over the mesh are not built for the {dom.NAME} domain")
        return refuse
    from ea_agent.domains.suo.scenario import load_plan
    doc = json.loads((Path(sc.root) / "plan.json").read_text(encoding="utf-8"))

    def validate(name: str, body: bytes):
        if len(body) > MAX_PLAN_BYTES:
            raise ValueError(f"plan {name}: {len(body)} bytes, over the {MAX_PLAN_BYTES} limit")
        key = (str(sc.root), name, hashlib.blake2b(body, digest_size=16).digest())
        if key in _CACHE:
            return _CACHE[key]
        try:
            missions = json.loads(body)
        except (ValueError, UnicodeDecodeError) as e:
            raise ValueError(f"plan {name}: not JSON ({str(e)[:120]})") from None
        plan = {"task_organization": doc["task_organization"], "plans": {name: missions}, "initial_plan": name}
        with tempfile.TemporaryDirectory(prefix="saim-plan-") as tmp:
            p = Path(tmp) / "plan.json"
            p.write_text(json.dumps(plan), encoding="utf-8")
            try:
                _, plans, _ = load_plan(p, sc.overlay)
            except ScenarioError as e:
                raise ValueError(str(e)) from None
        if len(_CACHE) > 64:
            _CACHE.clear()
        _CACHE[key] = plans[name]
        return plans[name]
    return validate
