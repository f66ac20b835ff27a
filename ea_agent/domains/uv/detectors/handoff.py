"""Handoff (reporting-requirement): agent-to-agent task messages (paper 7.2).

`delegate` A->B: B's own EA commits B to the task at once when B is patrolling (its
controller is told to accept: task `Accept`), within B's patrol sector else A's;
`accept` B->A: A's EA drops A's pursuit and the operator's EA moves it from A to B.

One handoff is one story (`story_key`): the handing robot's EA and the operator's
raise it once, at its first word (their own policy's "A hands pursuit of E to B" on
target-gone, else the accept), and the accept is an update of that story: its
candidate goes to VOA on the same key, where it keeps the story alive and is not
given again (`[voa.repeat] handoff = 0`). The receiver's EA raises its own ("delegated
to us"), which its own acceptance closes. After the accept the story is over: a later
handoff between the same robots is a story of its own.
`success`/`failure` end the sender's named mission (how an EA learns that a
teammate's step is done, which the partial order may wait for), after the epoch's
detectors ran on the states that came with the report (see `UvDomain.report_end`).
A robot's EA hears only the agent messages it sends or receives (its subscription);
the TEAM's hears all."""
from __future__ import annotations

from typing import TYPE_CHECKING

from ..messages import UvAgent

if TYPE_CHECKING:
    from ..domain import UvDomain


def story_key(dom: "UvDomain", frm: str, to: str, what: str, t: float, close: bool = False) -> tuple:
    """The VOA key of the story of handing `what` (a target, else a task) from `frm` to
    `to`: the same from the story's first word to the accept that ends it (`close`),
    so the accept is judged as an update of the alert already given; a handoff of the
    same after that, or after the story lay quiet for `[voa] expiry_s`, is a new story."""
    k = (frm, to, what)
    cur = dom.handoffs.get(k)
    if cur is None or t - cur[1] >= float(dom.cfg["voa"]["expiry_s"]):
        dom.handoff_n += 1
        cur = (dom.handoff_n, t)
    if close:
        dom.handoffs.pop(k, None)
    else:
        dom.handoffs[k] = (cur[0], t)
    return ("handoff", frm, to, what, cur[0])


def on_agent(dom: "UvDomain", f: UvAgent, cands: list) -> None:
    if f.act == "delegate":
        dom.delegations[(f.sender, f.to, f.task)] = f
        if f.to == dom.owner:   # we are asked: our robot takes the pursuit if it is patrolling
            target = f.target or _target_of(dom, f.task)
            if target and dom.policies.accepts(f.to):
                from ..tasks import Accept
                dom.policies.take_over(f.to, target, dom.patrol_sector(f.to) or dom.sector_of(f.task, f.sender), f.t,
                                       Accept, frm=f.sender, task=f.task)
            cands.append(_cand(dom, f, f.sender, f.to, target, "delegated to us"))
    elif f.act == "accept":
        d = dom.delegations.pop((f.to, f.sender, f.task), None)
        target = f.target or (d.target if d else None) or _target_of(dom, f.task)
        frm, to = f.to, f.sender
        if dom.owner == to:   # our own acceptance: the delegate already moved the task
            story_key(dom, frm, to, target or f.task, f.t, close=True)
            return
        if frm in dom.mine or to in dom.mine:
            dom.policies.transfer(frm, to, target, dom.patrol_sector(to) or dom.sector_of(f.task, frm), f.task, f.t)
            cands.append(_cand(dom, f, frm, to, target, "accepted", close=True))
    else:
        m = dom.missions.get(f.task)
        if m is not None and m.unit == f.sender and dom.plan is not None and \
                dom.plan.state.get(m.id) in ("active", "ready", "suspended"):
            dom.report_end(m, f.t, f.act)   # ended once this epoch's detectors have run


def _target_of(dom: "UvDomain", task: str) -> str | None:
    m = dom.missions.get(task)
    return m.params.get("target") if m is not None else None


def _cand(dom: "UvDomain", f: UvAgent, frm: str, to: str, target: str | None, how: str, close: bool = False):
    what = f"pursuit of {target}" if target else f"task {f.task}"
    return dom.cand(f.t, "handoff", None, tuple(x for x in (frm, to, target) if x),
                    f"{dom.name(frm)} handed {what} to {dom.name(to)} ({how})",
                    story_key(dom, frm, to, target or f.task, f.t, close), None,
                    {"from": frm, "to": to, "task": f.task, "target": target, "act": f.act})
