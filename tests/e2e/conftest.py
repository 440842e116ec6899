"""Shared browser fixture of the end-to-end tests: headless Chromium through its WebDriver,
skipped (saying why) only where Chromium, its driver or selenium is missing."""

from __future__ import annotations

import shutil

import pytest

CHROMIUM = ("chromium", "chromium-browser", "google-chrome")


def _start(width: int = 1400, height: int = 1000):
    """A headless Chromium whose viewport is exactly `width` × `height` CSS pixels."""
    try:
        from selenium import webdriver
        from selenium.common.exceptions import WebDriverException
        from selenium.webdriver.chrome.service import Service
    except ImportError as exc:  # the test extras were not installed
        pytest.skip(f"selenium is not installed ({exc}); `bash setup.sh` installs it")
    binary = next((shutil.which(b) for b in CHROMIUM if shutil.which(b)), None)
    driver_path = shutil.which("chromedriver")
    if binary is None or driver_path is None:
        pytest.skip("headless Chromium and chromium-driver are not installed (Debian: apt-get install chromium "
                    "chromium-driver; setup.sh does it)")
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                f"--window-size={width},{height}"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    try:
        driver = webdriver.Chrome(service=Service(driver_path), options=options)
    except WebDriverException as exc:
        pytest.skip(f"Chromium cannot start here: {str(exc).splitlines()[0]}")
    _viewport(driver, width, height)
    return driver


def _viewport(driver, width: int, height: int) -> None:
    """Make the page's viewport exactly this size (the window's frame is not part of it)."""
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                           {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})


@pytest.fixture(scope="module")
def chromium():
    """A browser for a module's tests, its viewport 1400 × 1000; `driver.viewport(w, h)` resizes it."""
    driver = _start()
    driver.viewport = lambda w, h: _viewport(driver, w, h)
    yield driver
    driver.quit()
