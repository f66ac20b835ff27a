"""The console on a live mesh, in a real browser (issue #9, "Tested in a real browser").

`mesh up --console` on the small scenario (BN's, A's and A2's EA peers, mTLS, access
control) at 60x real time; headless Chromium opens the printed address and acts as the
commander:
 - the first flash alert raised after the page opened is on screen within 1 s of falling
   due on the mesh's own clock (the console stamps the wall time it heard the sources'
   watermarks pass; the page logs when it drew each row: `window.__latencies()`);
 - clicking it shows its details; unacknowledged, its row is re-notified (never a new
   alert); acknowledged, the re-notifications stop (checked on BN's notice log once the
   mesh clock is well past the next ones, not after a sleep);
 - an urgent alert A2's commander leaves unacknowledged is escalated to A (a signed notice
   through the mesh): it is on the page as "unacknowledged at A2", in A2's notice log, and
   no alert anywhere changed priority (every peer's alerts have the unarmed run's priorities);
 - a threshold set from the page (A2's threat radius) shapes A2's next alerts: its first
   contact comes earlier and farther than in the run without the change;
 - the call for fire A2 must confirm is confirmed from the page;
 - then every command the peers took is in their command logs, and `saim-mesh run
   --commands` over those logs gives exactly the mesh's alerts: a run with a commander in
   the loop replays deterministically.
"""
from __future__ import annotations

import json
import re
import subprocess
import sys
import time

import pytest

from saim_mesh.launch.proc import Proc, clean_env, py

from .browser import chromium, js_errors
from .conftest import SMALL

pytestmark = pytest.mark.timeout(420)
SPEED = 60
BASELINE_A2_CONTACT_T = 5004.0   # A2's first contact with the default threat radius (2 km): see the check below


def wait(driver, cond, timeout=60, what="condition"):
    from selenium.webdriver.support.ui import WebDriverWait
    return WebDriverWait(driver, timeout).until(cond, message=f"no {what} within {timeout} s")


def plan_alerts(path):
    """The alerts of the plan (not the wall-clock presence notes), as comparable keys."""
    out = []
    for line in open(path):
        a = json.loads(line)
        if a["category"] == "system-problem":
            continue
        d = a["details"]
        out.append((a["t"], a["type"], tuple(a["subjects"]), a["message"], a["priority"], d.get("id"),
                    d.get("story"), d.get("silenced")))
    return out


def notices(path):
    try:
        return [json.loads(x) for x in open(path) if x.strip()]
    except FileNotFoundError:
        return []


@pytest.fixture(scope="module")
def mesh(tmp_path_factory):
    out = tmp_path_factory.mktemp("console-mesh")
    p = Proc("mesh-up", [*py(), "mesh", "up", str(SMALL), "--units", "BN", "A", "A2", "--speed", str(SPEED),
                         "--out-dir", str(out), "--console", "0", "--console-linger", "300"],
             env=clean_env(), log_dir=out)
    try:
        line = p.wait_for("http://127.0.0.1:", 120)
        yield line.split()[0], out, p
    finally:
        p.stop()   # SIGTERM: mesh up stops its children before it exits
        p.p.wait(30)
    pids = json.loads((out / "pids.json").read_text()) if (out / "pids.json").exists() else {}
    alive = [n for n, pid in pids.items() if _alive(pid)]
    assert not alive, f"children of mesh up still running: {alive}"


def _alive(pid) -> bool:
    import os
    try:
        os.kill(int(pid), 0)
    except (ProcessLookupError, ValueError, TypeError):
        return False
    except PermissionError:
        return True
    return not open(f"/proc/{int(pid)}/stat").read().split(") ", 1)[1].startswith("Z")


def test_a_commander_acts_on_a_live_mesh(mesh):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select
    url, out, proc = mesh
    with chromium() as d:
        d.get(url)
        wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, "#taskorg [data-unit]"), what="task organization")
        opened_ms = d.execute_script("return Date.now()")
        js = lambda src: d.execute_script(src)   # noqa: E731
        status = lambda: d.find_element(By.ID, "status").get_attribute("textContent")   # noqa: E731
        mesh_t = lambda: js("const k = window.__ticks; return k.length ? k[k.length - 1][0] : 0")   # noqa: E731

        # 1. the first flash raised after the page opened: on screen within 1 s of falling due
        def first_live_flash(d):
            live = [e for e in js("return window.__latencies()")
                    if e["priority"] == "flash" and e["due_ms"] is not None and e["due_ms"] >= opened_ms]
            return live[0] if live else None
        first = wait(d, first_live_flash, 120, "live flash alert")
        assert first["latency_ms"] <= 1000, first
        assert first["t_alert"] > 0 and first["owner"] == "BN"
        aid = first["id"]

        # 2. its details on a click; re-notified until acknowledged (the row, never a new alert)
        row = lambda: d.find_element(By.CSS_SELECTOR, f'#pane-flash li.story[data-story="{first["story"]}"]')  # noqa: E731
        row().click()
        wait(d, lambda d: aid in d.find_element(By.ID, "details").get_attribute("textContent"), what="details")
        assert first["message"] in d.find_element(By.ID, "details").get_attribute("textContent")
        renotified = lambda: [n for n in notices(out / "BN.notify.jsonl")   # noqa: E731
                              if n["kind"] == "renotify" and n["alert"] == aid]
        wait(d, lambda d: renotified(), 60, f"re-notification of {aid}")
        wait(d, lambda d: "renotified" in (row().get_attribute("class") or ""), 30, "the row re-notified")
        assert not any(a["details"].get("id") != aid and a["details"].get("story") == first["story"]
                       and a["message"] == first["message"] for a in map(json.loads, open(out / "BN.jsonl")))
        row().click()
        d.find_element(By.ID, "ack-btn").click()
        wait(d, lambda d: status().startswith("ack BN: ok at H+"), 30, "ack result")
        log_ack = _wait_logged(out / "BN.cmdlog", "ack", proc)
        assert log_ack["ok"] and log_ack["cmd"]["alert"] == aid
        every = 120.0   # [notify.flash] every_s
        wait(d, lambda d: mesh_t() >= log_ack["t"] + 2 * every, 60, "mesh clock two re-notification periods on")
        after = [n for n in renotified() if n["t"] > log_ack["t"]]
        assert after == [], f"{aid} re-notified after its ack at t={log_ack['t']}: {after}"

        # an escalation from below reaches the superiors (A2 -> A, A -> BN): on the page, as A2's EA
        # sent it (its notice log: the superiors' EAs do not log what they receive)
        esc = wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, "#escalations li.escalation"), 120, "escalation")
        assert "unacknowledged at" in esc[0].get_attribute("textContent")
        sent = wait(d, lambda d: [n for n in notices(out / "A2.notify.jsonl")
                                  if n["kind"] == "escalate" and n["owner"] == "A2" and n["to"] == "A"], 60,
                    "A2's escalation to A in A2's notice log")
        assert sent[0]["priority"] in ("flash", "immediate")

        # 3. A2's threat radius from 2 km to 4 km, from the page: A2's next contact follows it
        Select(d.find_element(By.ID, "unit-select")).select_by_value("A2")
        assert mesh_t() < 4000, "too late in the scenario for the threshold check (machine too slow?)"
        Select(d.find_element(By.ID, "set-key")).select_by_value("voi.threat_radius_m")
        d.find_element(By.ID, "set-value").clear()
        d.find_element(By.ID, "set-value").send_keys("4000")
        d.find_element(By.ID, "set-btn").click()
        wait(d, lambda d: status().startswith("set A2: ok at H+"), 30, "set result")

        def a2_contact(d):
            c = [e for e in js("return window.__renderLog") if e["owner"] == "A2" and e["type"] == "contact"]
            return c[0] if c else None
        contact = wait(d, a2_contact, 120, "A2 contact alert")
        km = float(re.search(r"([\d.]+) km", contact["message"]).group(1))
        assert contact["t_alert"] < BASELINE_A2_CONTACT_T and km > 2.0, contact

        # 4. the call for fire A2 must confirm, confirmed from the page
        wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, '#pane-flash li.alert[data-type="call-for-fire"]'),
             60, "call-for-fire alert")
        d.find_element(By.ID, "cff-id").clear()
        d.find_element(By.ID, "cff-id").send_keys("CFF-1")
        d.find_element(By.ID, "cff-confirm-btn").click()
        wait(d, lambda d: status().startswith("cff A2: ok at H+"), 30, "cff result")
        bad = [e for e in js_errors(d) if "400" not in e]   # Chromium logs every 4xx response
        assert bad == [], bad

    # 5. the peers end; a replay of their command logs gives exactly their alerts
    units = ("BN", "A", "A2")
    for u in units:
        _wait_line(out / "logs" / f"{u}.log", "summary ", proc)
    cmds = [out / f"{u}.cmdlog" for u in units if (out / f"{u}.cmdlog").exists()]
    kinds = [json.loads(x)["kind"] for f in cmds for x in open(f)]
    assert sorted(k for k in kinds if not k.startswith("dir.")) == ["ack", "set"], kinds
    # the call for fire's confirmation is a directive (saim_mesh/authority/directives.py): A2's EA has it in
    # its input journal; a directive it took is in its command log as `dir.<kind>`, replayed below too
    assert b"cff-confirm" in (out / "A2.input").read_bytes()
    replay, unarmed = out / "replay.jsonl", out / "unarmed.jsonl"
    subprocess.run([sys.executable, "-m", "saim_mesh", "run", str(SMALL), "--ea", *units, "--armed", "--quiet",
                    "--commands", *map(str, cmds), "--out", str(replay)], check=True, env=clean_env(),
                   stdout=subprocess.DEVNULL, timeout=300)
    subprocess.run([sys.executable, "-m", "saim_mesh", "run", str(SMALL), "--ea", *units, "--quiet",
                    "--commands", *map(str, cmds), "--out", str(unarmed)], check=True, env=clean_env(),
                   stdout=subprocess.DEVNULL, timeout=300)

    def by_owner(path) -> dict[str, list]:
        got: dict[str, list] = {u: [] for u in units}
        for line in open(path):
            a = json.loads(line)
            if a["category"] != "system-problem":
                d = a["details"]
                got[a["owner"]].append((a["t"], a["type"], tuple(a["subjects"]), a["message"], a["priority"],
                                        d.get("id"), d.get("story"), d.get("silenced")))
        return got
    armed_run, unarmed_run = by_owner(replay), by_owner(unarmed)
    for u in units:
        assert plan_alerts(out / f"{u}.jsonl") == armed_run[u], u
        # a commander watching changes what is re-notified and escalated, never an alert or its priority
        assert armed_run[u] == unarmed_run[u], u


def _wait_line(path, prefix: str, proc: Proc, timeout: float = 180.0) -> str:
    """A line starting with `prefix` in a child's log (the mesh must still be up)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.exists():
            for line in path.read_text(errors="replace").splitlines():
                if line.startswith(prefix):
                    return line
        assert proc.p.poll() is None, f"mesh up exited ({proc.p.returncode}): {proc.tail()}"
        time.sleep(0.05)
    raise TimeoutError(f"no '{prefix}' in {path} within {timeout} s")


def _wait_logged(path, kind: str, proc: Proc, timeout: float = 30.0) -> dict:
    """The first `kind` command in a peer's command log."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.exists():
            for line in path.read_text().splitlines():
                if line.strip() and json.loads(line)["kind"] == kind:
                    return json.loads(line)
        assert proc.p.poll() is None, f"mesh up exited ({proc.p.returncode}): {proc.tail()}"
        time.sleep(0.05)
    raise TimeoutError(f"no {kind} command in {path} within {timeout} s")
