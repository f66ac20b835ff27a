"""The console in a real browser (headless Chromium from the distribution, Selenium):
the page loads with no script error, shows the run's alerts in their priority panes,
shows an alert's details on a click, acknowledges it, and reports a bad threshold as
an error without changing anything."""
from __future__ import annotations

import subprocess
import sys

import pytest

from saim_mesh.proc import Proc, clean_env

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


def wait(driver, cond, timeout=20):
    from selenium.webdriver.support.ui import WebDriverWait
    return WebDriverWait(driver, timeout).until(cond)


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
        assert options[0] == "execute:BN-branch-ABF" and set(options) == {"abort", "execute:BN-branch-ABF", "continue"}
        assert "recommended" in buttons[0].get_attribute("class")
        go_on = next(b for b in buttons if b.get_attribute("data-option") == "continue")
        d.execute_script("arguments[0].scrollIntoView(); arguments[0].click();", go_on)
        status = lambda: d.find_element(By.ID, "status").get_attribute("textContent")
        wait(d, lambda d: "decide" in status().lower())
        assert ": ok" in status(), status()
        wait(d, lambda d: "decided: continue" in d.find_element(By.ID, "details").get_attribute("textContent"))
        bad = [e for e in js_errors(d) if "400" not in e]
        assert bad == [], bad
