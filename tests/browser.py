"""Headless Chromium from the distribution (chromium, chromium-driver), driven by
Selenium, for the console's browser tests. Skips with the reason when the system
browser is absent (scripts/test installs it where it can: scripts/_browser.sh)."""
from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager

import pytest

CHROMIUM, DRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--no-first-run", "--disable-sync", "--disable-quic",
         "--window-size=1400,900"]


def skip_reason() -> str | None:
    if os.environ.get("SAIM_NO_BROWSER"):
        return os.environ["SAIM_NO_BROWSER"]
    if not (os.path.exists(CHROMIUM) and os.path.exists(DRIVER)):
        return f"no system browser ({CHROMIUM}, {DRIVER}): apt-get install chromium chromium-driver"
    return None


@contextmanager
def chromium():
    """A fresh headless browser with its own profile, always quit."""
    why = skip_reason()
    if why:
        pytest.skip(why)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    profile = tempfile.mkdtemp(prefix="saim-chromium-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for f in [*FLAGS, f"--user-data-dir={profile}"]:
        opts.add_argument(f)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(DRIVER), options=opts)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def js_errors(driver) -> list[str]:
    return [e["message"] for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
