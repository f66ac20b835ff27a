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
