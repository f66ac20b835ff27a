"""The console in a real browser (headless Chromium from the distribution, Selenium):
the page loads with no script error, shows the run's alerts in their priority panes,
shows an alert's details on a click, acknowledges it, and reports a bad threshold as
an error without changing anything."""
from __future__ import annotations

import subprocess
import sys

import pytest

from saim_mesh.launch.proc import Proc, clean_env

from .browser import chromium, js_errors
from .conftest import ROOT, SMALL

pytestmark = pytest.mark.timeout(240)


@pytest.fixture(scope="module")
def console():
    p = Proc("run-console", [sys.executable, "-m", "saim_mesh", "run", str(SMALL), "--ea", "BN", "A2", "--speed", "max",
                             "--quiet", "--console", "0", "--linger", "120"], env=clean_env())
    try:
        url = p.wait_for("console http", 120).split(" ", 1)[1].strip()
        p.wait_for("console: serving", 120)   # the run is over: every alert is in
        yield url
    finally:
        p.stop()
    assert p.p.poll() is not None


def wait(driver, cond, timeout=20, what=""):
    from selenium.webdriver.support.ui import WebDriverWait
    return WebDriverWait(driver, timeout).until(cond, what)


def test_the_page_shows_alerts_and_acts_on_them(console):
    from selenium.webdriver.common.by import By
    with chromium() as d:
        d.get(console)
        flash = wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, "#pane-flash li.alert"))
        assert d.find_elements(By.CSS_SELECTOR, "#pane-immediate li.alert, #pane-priority li.alert")
        assert d.find_element(By.ID, "clock").text.startswith("H+")
        assert d.find_elements(By.CSS_SELECTOR, "#taskorg [data-unit]")
        counts = lambda: d.find_element(By.ID, "counts").get_attribute("textContent")   # may be out of view
        wait(d, lambda d: "fratricide" in counts() and "A2" in counts())
        first = flash[0]
        aid = first.get_attribute("data-id")
        first.click()
        wait(d, lambda d: aid in d.find_element(By.ID, "details").get_attribute("textContent"))
        d.find_element(By.ID, "ack-btn").click()
        status = lambda: d.find_element(By.ID, "status").get_attribute("textContent")
        wait(d, lambda d: "ack" in status().lower())
        assert ": ok" in status() and '"ok":true' in status(), status()
        d.find_element(By.ID, "set-value").clear()
        d.find_element(By.ID, "set-value").send_keys("-5")
        d.find_element(By.ID, "set-btn").click()
        wait(d, lambda d: "> 0" in status())
        bad = [e for e in js_errors(d) if "400" not in e]   # Chromium logs every 4xx response
        assert bad == [], bad


def test_a_silence_by_area_is_listed_and_lifted_from_the_page(console):
    """Silence by a control measure's name (offered from the overlay), see it in force with
    its area, lift it with its button: each step answered by the EA."""
    from selenium.webdriver.common.by import By
    with chromium() as d:
        d.get(console)
        wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, "#overlay-ids option[value='OBJ-A']"))
        d.find_element(By.ID, "silence-area").send_keys("OBJ-A")
        d.find_element(By.ID, "silence-comment").send_keys("assault expected")
        d.find_element(By.ID, "silence-btn").click()
        rows = lambda d: d.find_elements(By.CSS_SELECTOR, "#silences li.silence")   # noqa: E731
        wait(d, lambda d: len(rows(d)) == 1)
        text = rows(d)[0].text
        assert "areas OBJ-A" in text and "assault expected" in text and text.startswith("BN:"), text
        status = lambda: d.find_element(By.ID, "status").get_attribute("textContent")   # noqa: E731
        assert "silence" in status() and ": ok" in status(), status()
        rows(d)[0].find_element(By.CSS_SELECTOR, "button.lift").click()
        wait(d, lambda d: len(rows(d)) == 0)
        wait(d, lambda d: "unsilence" in status() and ": ok" in status())
        d.find_element(By.ID, "silence-area").clear()
        d.find_element(By.ID, "silence-area").send_keys("NOWHERE")
        d.find_element(By.ID, "silence-btn").click()
        wait(d, lambda d: "unknown area 'NOWHERE'" in status())
        assert len(rows(d)) == 0
        bad = [e for e in js_errors(d) if "400" not in e]
        assert bad == [], bad


def test_a_decision_is_taken_from_the_alert_that_asks_for_it(console):
    """BN's EA asks whether M goes on past H9 (threat-ahead): the alert's details show one
    button per option, the recommended one first; a click sends `decide` and the EA answers."""
    from selenium.webdriver.common.by import By
    with chromium() as d:
        d.get(console)
        asks = wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, 'li.alert[data-type="threat-ahead"][data-owner="BN"]'))
        d.execute_script("arguments[0].scrollIntoView(); arguments[0].click();", asks[0])   # in a scrolled pane
        buttons = wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, "#details .decision button.decide"))
        options = [b.get_attribute("data-option") for b in buttons]
        branch = "execute:BN-branch-disrupt"
        assert options[0] == branch and set(options) == {"abort", branch, "continue"}
        assert "recommended" in buttons[0].get_attribute("class")
        go_on = next(b for b in buttons if b.get_attribute("data-option") == "continue")
        d.execute_script("arguments[0].scrollIntoView(); arguments[0].click();", go_on)
        status = lambda: d.find_element(By.ID, "status").get_attribute("textContent")
        wait(d, lambda d: "decide" in status().lower())
        assert ": ok" in status(), status()
        wait(d, lambda d: "decided: continue" in d.find_element(By.ID, "details").get_attribute("textContent"))
        bad = [e for e in js_errors(d) if "400" not in e]
        assert bad == [], bad


# -- a commander who watches is never flooded (issue 30): stories, quiet, notices ----------
# In process, in this test's own process: BN, A and A2 armed (as under `run --console`),
# the run stopping at the scenario times a test names (`Stepped.to`), the page in headless
# Chromium showing what a person sees. Every wait is on a condition of the page or the EAs.

import math
import threading
from collections import Counter

OWNERS = ["BN", "A", "A2"]
PANES = ("flash", "immediate", "priority", "routine")


class Stepped:
    """An in-process run with the console served over it, stopped before the first event
    at or after the time it was sent to, its EAs brought to that time (as a paced run
    does between events); nobody acknowledges unless the test does."""

    def __init__(self, sc, owners=OWNERS, overrides=None):
        from saim_mesh.console.feed import serve_inprocess
        from saim_mesh.inprocess.runner import run
        self.cv = threading.Condition()
        self.target, self.at, self.done, self.error = 0.0, None, False, None
        self.server = self.state = None
        self.eas: list = []
        made = threading.Event()

        def on_made(eas):
            self.server, self.state = serve_inprocess(eas, sc, 0)
            self.eas = eas
            inner = eas[0].submit   # the console's hook (under its lock); we stop outside it

            def submit(m, *a):
                while m.t >= self.target:
                    self._stop(m.t)
                return inner(m, *a)
            eas[0].submit = submit
            made.set()

        def go():
            try:
                run(sc, owners, armed=True, on_made=on_made, overrides=overrides)
            except BaseException as e:   # noqa: BLE001 (said by `to`)
                self.error = e
            finally:
                with self.cv:
                    self.done = True
                    self.cv.notify_all()
                made.set()
        self.thread = threading.Thread(target=go, name="stepped-run", daemon=True)
        self.thread.start()
        assert made.wait(60) and self.error is None, self.error
        self.url = self.server.url
        self.ea = {ea.owner: ea for ea in self.eas}

    def _stop(self, t: float) -> None:
        target = self.target
        for ea in self.eas:   # epochs, alerts and notices due by then are out
            ea.advance(target)
        with self.cv:
            self.at = target
            self.cv.notify_all()
            self.cv.wait_for(lambda: self.target > t)

    def to(self, t: float, timeout: float = 60.0) -> None:
        with self.cv:
            self.at, self.target = None, t
            self.cv.notify_all()
            assert self.cv.wait_for(lambda: self.at == t or self.done, timeout), f"the run never reached t={t}"
        assert self.error is None, self.error

    def id(self, label: str) -> str:
        """The id of what this file calls `BN/4`: the 4th alert BN's EA raised in this run
        (ids say what an alert is, `BN/814.1a2b`; a rank is how a test can name one)."""
        owner, n = label.split("/")
        return self.ea[owner].alerts[int(n) - 1].details["id"]

    def close(self) -> None:
        self.to(math.inf)
        self.thread.join(30)
        self.server.stop()


@pytest.fixture
def stepped(small):
    s = Stepped(small)
    try:
        yield s
    finally:
        s.close()


def shown(d, pane: str) -> list:
    from selenium.webdriver.common.by import By
    return d.find_elements(By.CSS_SELECTOR, f"#pane-{pane} li.story")


def attr(d, css: str, name: str):
    """An attribute of the first element matching `css`, or None (rows come and go)."""
    return d.execute_script("const e = document.querySelector(arguments[0]); return e ? e.getAttribute(arguments[1]) : null",
                            css, name)


def text(d, el_id: str) -> str:
    return d.execute_script("const e = document.getElementById(arguments[0]); return e ? e.textContent : ''", el_id)


def expected_stories(ea) -> dict[str, Counter]:
    """From the EA's own alert log: per pane, the stories a person should see (the
    story's most urgent alert gives its pane; silenced and inhibited alerts are not shown)."""
    by_story: dict[str, list] = {}
    for a in ea.alerts:
        if "silenced" in a.details or "inhibited_by" in a.details:
            continue
        by_story.setdefault(a.details["story"], []).append(a)
    panes: dict[str, Counter] = {p: Counter() for p in PANES}
    for sid, alerts in by_story.items():
        pane = min((a.priority for a in alerts), key=PANES.index)
        panes[pane][sid] = len(alerts)
    return panes


def test_a_pane_counts_stories_and_folds_a_storys_alerts(stepped):
    """Each pane has one row per story, its header counts stories, and a story of several
    alerts (an out-of-position and its VOA update) is one row with its count; a click shows
    the newest alert with the folded ones, newest first."""
    I = stepped.id   # noqa: E741, N806
    from selenium.webdriver.common.by import By
    stepped.to(1300.0)
    want = expected_stories(stepped.ea["BN"])
    assert want["immediate"][I("BN/4")] == 2   # BN/4 (C off its corridor, immediate), then BN/7 (its update)
    with chromium() as d:
        d.get(stepped.url)
        for p in PANES:
            n = sum(1 for _ in want[p])
            wait(d, lambda d: text(d, f"count-{p}") == str(n) and len(shown(d, p)) == n)
            got = {e.get_attribute("data-story"): int(e.get_attribute("data-count")) for e in shown(d, p)}
            assert got == dict(want[p]), (p, got)
        row = d.find_element(By.CSS_SELECTOR, f'#pane-immediate li.story[data-story="{I("BN/4")}"]')
        assert row.find_element(By.CSS_SELECTOR, ".story-count").text.strip().endswith("2")
        assert (row.get_attribute("data-id"), row.get_attribute("data-type"), row.get_attribute("data-owner"),
                row.get_attribute("data-priority")) == (I("BN/7"), "out-of-position", "BN", "immediate")
        assert float(row.get_attribute("data-t")) == 814.0
        d.execute_script("arguments[0].scrollIntoView(); arguments[0].click();", row)
        folded = wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, "#details ol.story-alerts li"))
        assert [li.get_attribute("data-id") for li in folded] == [I("BN/7"), I("BN/4")]
        assert I("BN/7") in text(d, "details")
        assert js_errors(d) == []


def test_a_silence_empties_a_pane_and_its_alerts_go_quiet(stepped):
    """Silencing out-of-position on BN from the page takes BN's out-of-position stories out
    of the panes into the quiet view; the later ones come marked silenced by the EA (still
    in its alert log), never in a pane; lifting the silence brings the stories back."""
    I = stepped.id   # noqa: E741, N806
    from selenium.webdriver.common.by import By
    stepped.to(1000.0)
    oop = 'li.story[data-type="out-of-position"][data-owner="BN"]'
    stories = {a.details["story"] for a in stepped.ea["BN"].alerts if a.type == "out-of-position"}
    assert stories == {I("BN/3"), I("BN/4"), I("BN/9"), I("BN/11")}
    with chromium() as d:
        d.get(stepped.url)
        wait(d, lambda d: {e.get_attribute("data-story") for e in d.find_elements(By.CSS_SELECTOR, f"#pane-immediate {oop}")}
             == stories, what="out-of-position stories in the immediate pane")
        before = int(text(d, "count-immediate"))
        d.find_element(By.ID, "silence-type").send_keys("out-of-position")
        d.find_element(By.ID, "silence-btn").click()
        silences = lambda d: d.find_elements(By.CSS_SELECTOR, "#silences li.silence")   # noqa: E731
        wait(d, lambda d: len(silences(d)) == 1)
        sid = silences(d)[0].get_attribute("data-id")
        wait(d, lambda d: not d.find_elements(By.CSS_SELECTOR, f"#alerts .alert-list {oop}"), what="panes emptied")
        wait(d, lambda d: int(text(d, "count-immediate")) == before - 4, what="pane count")
        d.find_element(By.ID, "quiet-toggle").click()
        quiet = lambda d: {e.get_attribute("data-id") for e in d.find_elements(By.CSS_SELECTOR, "#pane-quiet li.alert")}   # noqa: E731
        wait(d, lambda d: d.find_element(By.ID, "pane-quiet").is_displayed() and {I("BN/10"), I("BN/7"), I("BN/9"), I("BN/11")} <= quiet(d),
             what="the silenced stories in the quiet view")
        stepped.to(1150.0)   # BN/13 (story BN/9) and BN/15 (story BN/11) are raised under the silence
        wait(d, lambda d: {I("BN/13"), I("BN/15")} <= quiet(d))
        logged = {a.details["id"]: a for a in stepped.ea["BN"].alerts}
        assert logged[I("BN/13")].details["silenced"] == sid and logged[I("BN/15")].details["silenced"] == sid
        assert not d.find_elements(By.CSS_SELECTOR, f"#alerts .alert-list {oop}")
        assert not d.find_elements(By.CSS_SELECTOR, f'#pane-priority li[data-id="{I("BN/13")}"], #pane-priority li[data-id="{I("BN/15")}"]')
        why = d.find_element(By.CSS_SELECTOR, f'#pane-quiet li.alert[data-id="{I("BN/13")}"]').text
        assert f"silenced by {sid}" in why, why
        silences(d)[0].find_element(By.CSS_SELECTOR, "button.lift").click()
        wait(d, lambda d: len(silences(d)) == 0)
        wait(d, lambda d: len(d.find_elements(By.CSS_SELECTOR, f"#pane-immediate {oop}")) == 4, what="shown again")
        assert {I("BN/13"), I("BN/15")} <= quiet(d)   # what the EA marked stays quiet
        assert js_errors(d) == []


def test_an_inhibition_rule_from_the_page_quiets_its_targets(stepped):
    """`while contact, quiet distance sharing subjects` on BN, from the page: the distance
    alerts BN raises about the units and tracks in contact never reach a pane, are logged by
    the EA marked inhibited_by (rule, source), and the rule is listed until lifted."""
    I = stepped.id   # noqa: E741, N806
    from selenium.webdriver.common.by import By
    stepped.to(2200.0)
    with chromium() as d:
        d.get(stepped.url)
        wait(d, lambda d: text(d, "clock") == "H+00:36:40")
        d.find_element(By.ID, "inhibit-source-type").send_keys("contact")
        d.find_element(By.ID, "inhibit-target-type").clear()
        d.find_element(By.ID, "inhibit-target-type").send_keys("distance")
        assert d.find_element(By.ID, "inhibit-equal").get_attribute("value") == "subjects"
        d.find_element(By.ID, "inhibit-id").send_keys("contact-mutes-distance")
        d.find_element(By.ID, "inhibit-btn").click()
        rules = lambda d: d.find_elements(By.CSS_SELECTOR, "#inhibits li.inhibit")   # noqa: E731
        wait(d, lambda d: [r.get_attribute("data-id") for r in rules(d)] == ["contact-mutes-distance"])
        assert "contact-mutes-distance" in stepped.ea["BN"].notify.inhibitor.rules
        stepped.to(2600.0)   # contacts BN/29 (R, H2) and BN/32 (M, H9); distances BN/34, BN/36, BN/38 about them
        d.find_element(By.ID, "quiet-toggle").click()
        quiet = lambda d: {e.get_attribute("data-id") for e in d.find_elements(By.CSS_SELECTOR, "#pane-quiet li.alert")}   # noqa: E731
        wait(d, lambda d: {I("BN/34"), I("BN/36"), I("BN/38")} <= quiet(d))
        wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, f'#pane-flash li.story[data-story="{I("BN/29")}"]'))
        assert not d.find_elements(By.CSS_SELECTOR, '#alerts .alert-list li.story[data-type="distance"]')
        logged = {a.details["id"]: a for a in stepped.ea["BN"].alerts}
        assert logged[I("BN/34")].details["inhibited_by"] == {"rule": "contact-mutes-distance", "source": I("BN/29")}
        assert logged[I("BN/36")].details["inhibited_by"]["source"] == I("BN/32")
        assert "inhibited by rule contact-mutes-distance" in \
            d.find_element(By.CSS_SELECTOR, f'#pane-quiet li.alert[data-id="{I("BN/34")}"]').text
        rules(d)[0].find_element(By.CSS_SELECTOR, "button.lift").click()
        wait(d, lambda d: not rules(d))
        assert stepped.ea["BN"].notify.inhibitor.rules == {}
        bad = [e for e in js_errors(d) if "400" not in e]
        assert bad == [], bad


def test_a_renotified_story_blinks_at_the_top_until_acknowledged(stepped):
    """Nobody acknowledged BN/3 (out-of-position, immediate, at 666): at 966 its EA tells
    the commander again; the story's row goes to the top of its pane and blinks; the ack
    from the page stops the EA's re-notifications and the blinking."""
    I = stepped.id   # noqa: E741, N806
    from selenium.webdriver.common.by import By
    stepped.to(985.0)
    assert [(n.kind, n.alert, n.count) for n in stepped.ea["BN"].notices] == [("renotify", I("BN/3"), 1)]
    row = f'#pane-immediate li.story[data-story="{I("BN/3")}"]'
    with chromium() as d:
        d.get(stepped.url)
        wait(d, lambda d: "renotified" in (attr(d, row, "class") or "") and attr(d, row, "data-renotified") == "1")
        assert shown(d, "immediate")[0].get_attribute("data-story") == I("BN/3")   # on top, though older than BN/4, BN/9
        blink = d.execute_script("return getComputedStyle(document.querySelector(arguments[0])).animationName", row)
        assert blink == "renotify"
        d.execute_script("arguments[0].click()", d.find_element(By.CSS_SELECTOR, row))
        wait(d, lambda d: I("BN/10") in text(d, "details"))
        d.find_element(By.ID, "ack-btn").click()
        wait(d, lambda d: "renotified" not in (attr(d, row, "class") or "") and I("BN/3") in stepped.ea["BN"].notify.acked)
        assert I("BN/3") not in stepped.ea["BN"].notify.chains
        assert ": ok" in text(d, "status"), text(d, "status")
        stepped.to(1400.0)   # its next re-notification was due at 1266: none comes
        assert [n for n in stepped.ea["BN"].notices if n.alert == I("BN/3")] == [stepped.ea["BN"].notices[0]]
        assert "renotified" not in (attr(d, row, "class") or "")
        d.refresh()   # a page opened after the ack: told again once, answered, not blinking
        wait(d, lambda d: attr(d, row, "data-renotified") == "1", what="the story after a reload")
        assert "renotified" not in attr(d, row, "class") and "acked" in attr(d, row, "class")
        assert js_errors(d) == []


def test_an_escalation_reaches_the_superiors_page(stepped):
    """A/2 (A2 out of position, immediate, at 942; A/1 is R's zone reconnaissance behind, at 456)
    unacknowledged at A for escalate_s (300 s):
    A's EA escalates it to BN; BN's page lists "unacknowledged at A: ..." and shows the
    original alert on a click, and BN's commander acknowledges it on A's EA."""
    I = stepped.id   # noqa: E741, N806
    from selenium.webdriver.common.by import By
    stepped.to(1280.0)
    [up] = [n for n in stepped.ea["A"].notices if n.kind == "escalate" and n.alert == I("A/2")]
    assert up.to == "BN" and up.owner == "A" and up.t == 942.0 + 300.0
    esc = f'#escalations li.escalation[data-alert="{I("A/2")}"][data-owner="A"]'
    with chromium() as d:
        d.get(stepped.url)
        assert Select(d.find_element(By.ID, "unit-select")).first_selected_option.get_attribute("value") == "BN"
        li = wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, esc))[0]
        assert li.text.startswith(f"unacknowledged at A: {up.message}"), li.text
        assert d.find_elements(By.CSS_SELECTOR, f'#escalations li.escalation[data-alert="{I("A2/1")}"][data-owner="A2"]')   # to A
        assert not d.find_elements(By.CSS_SELECTOR, '#pane-immediate li[data-owner="A"]')   # BN's panes: BN's stories
        li.find_element(By.CSS_SELECTOR, "button.show").click()
        wait(d, lambda d: attr(d, "#ack-btn", "data-alert") == I("A/2"))
        assert up.message in text(d, "details")
        d.find_element(By.ID, "ack-btn").click()
        wait(d, lambda d: "acked" in (attr(d, esc, "class") or ""))
        assert text(d, "status").startswith("ack A: ok"), text(d, "status")
        assert I("A/2") in stepped.ea["A"].notify.acked and I("A/2") not in stepped.ea["A"].notify.chains
        assert js_errors(d) == []


def Select(el):   # noqa: N802 (selenium's name)
    from selenium.webdriver.support.ui import Select as S
    return S(el)


def test_the_counts_table_fills_for_the_selected_unit_from_its_first_alert(stepped):
    """The Fig. 7 table shows the selected unit's column (and the units under it that
    raised alerts) from before its first alert, and counts that alert as it comes."""
    from selenium.webdriver.common.by import By
    stepped.to(300.0)   # before any alert
    col = lambda d, u: [td.get_attribute("textContent") for td in   # noqa: E731
                        d.find_elements(By.CSS_SELECTOR, f'#counts tbody td[data-owner="{u}"]')]
    heads = lambda d: [th.get_attribute("textContent") for th in d.find_elements(By.CSS_SELECTOR, "#counts thead th")]   # noqa: E731
    with chromium() as d:
        d.get(stepped.url)
        wait(d, lambda d: heads(d) == ["alert type", "BN"] and col(d, "BN") == ["0"], what="BN's empty column")
        stepped.to(340.0)   # BN/1, schedule, at 330
        wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, '#counts tr[data-type="schedule"] td[data-owner="BN"]'),
             what="BN's first alert counted")
        assert d.find_element(By.CSS_SELECTOR, '#counts tr[data-type="schedule"] td[data-owner="BN"]').text == "1"
        Select(d.find_element(By.ID, "unit-select")).select_by_value("A2")
        wait(d, lambda d: heads(d) == ["alert type", "A2"] and col(d, "A2") == ["0"], what="A2's empty column")
        stepped.to(950.0)   # A2/1, out-of-position, at 942
        cell = '#counts tr[data-type="out-of-position"] td[data-owner="A2"]'
        wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, cell), what="A2's first alert counted")
        assert d.find_element(By.CSS_SELECTOR, cell).text == "1"
        Select(d.find_element(By.ID, "unit-select")).select_by_value("A")
        wait(d, lambda d: heads(d)[:3] == ["alert type", "A", "A2"], what="A and the units under it")
        assert js_errors(d) == []


def test_thousands_of_stories_stay_responsive(small):
    """Thousands of stories (synthetic, one EA: 3,000 stories, 4,500 alerts, then 1,500 live
    at about 1,000/s): each pane draws its newest 200 stories with the rest counted exactly,
    a story's row keeps its count, and the page keeps up. The targets (first paint <= 1 s,
    render p99 <= 100 ms) are the bench's (scripts/bench_console, battalion through the
    mesh); here, on a shared test machine, three times them guards against a regression
    (measured alone on 2 CPUs: first paint 0.5-0.7 s, render p99 30-70 ms)."""
    import time as _time

    from selenium.webdriver.common.by import By

    from ea_agent import domains
    from saim_mesh.protocol import messages as M
    from saim_mesh.console.server import Server, make_app
    from saim_mesh.console.state import State

    types = sorted(domains.of(small).ALERT_TYPES)
    st = State(small, "BN", actors=["BN"])
    told: dict[str, list[str]] = {}   # story -> the priorities of its alerts
    n = 0

    def truth() -> dict[str, dict[str, int]]:   # pane (the story's most urgent alert) -> story -> alerts
        out: dict[str, dict[str, int]] = {p: {} for p in PANES}
        for sid, ps in told.items():
            out[min(ps, key=PANES.index)][sid] = len(ps)
        return out

    def raise_(story: int, prio: str, t: float) -> None:
        nonlocal n
        n += 1
        sid = f"BN/s{story}"
        a = M.Alert(t, "BN", types[story % len(types)], "adversarial-activity", prio, (f"T{story}",),
                    f"threat {story} (alert {n})", {"id": f"BN/{n}", "story": sid})
        st.clock(t, w=_time.time())
        st.alert(a)
        told.setdefault(sid, []).append(prio)
    for i in range(3000):   # 3,000 stories, half of them told twice
        raise_(i, PANES[i % 4], 10.0 + i)
    for i in range(0, 3000, 2):
        raise_(i, PANES[i % 4], 3100.0 + i)
    st.drain()
    server = Server(make_app(st, object()), 0)   # no actions asked of it
    url = server.start()
    try:
        with chromium() as d:
            d.get(url)
            first = wait(d, lambda d: d.execute_script("return window.__firstPaintMs"), 30, "first paint")
            assert first <= 3 * 1000, f"first paint {first} ms"
            want = truth()
            for p in PANES:
                assert len(shown(d, p)) == 200 and text(d, f"count-{p}") == str(len(want[p]))
                assert text(d, f"more-{p}").startswith(f"{len(want[p]) - 200} more")
            before = d.execute_script("return window.__renderLog.length")

            def live():   # 1,500 alerts at about 1,000/s: 500 new stories, 1,000 updates
                for k in range(1500):
                    raise_(3000 + k if k % 3 == 0 else k * 2 % 3000, PANES[k % 4], 7000.0 + k)
                    if k % 10 == 9:
                        _time.sleep(0.01)
            threading.Thread(target=live, daemon=True).start()
            wait(d, lambda d: d.execute_script("return window.__alertsSeen") == n == 6000, 60, "every alert")
            lat = [e["render_ms"] for e in d.execute_script("return window.__latencies()")[before:]]
            assert len(lat) == 1500
            lat.sort()
            p99 = lat[int(0.99 * len(lat))]
            assert p99 <= 3 * 100, f"render p99 {p99:.1f} ms (max {lat[-1]:.1f}; first paint {first} ms)"
            want = truth()
            for p in PANES:
                wait(d, lambda d: text(d, f"count-{p}") == str(len(want[p])), 10, f"{p} count")
                top = shown(d, p)[0]
                assert want[p][top.get_attribute("data-story")] == int(top.get_attribute("data-count"))
            assert js_errors(d) == []
    finally:
        server.stop()
