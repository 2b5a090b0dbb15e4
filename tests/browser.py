"""Headless Chromium for the report tests (system Chromium and chromedriver, never a download)."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pytest

INSTALL_HINT = ("install Chromium and its driver to run the browser tests: "
                "sudo apt-get install chromium chromium-driver (Debian/Ubuntu)")

ARTIFACTS = Path(__file__).resolve().parent.parent / "test-artifacts"


def _find(*names: str) -> str | None:
    for name in names:
        path = shutil.which(name)
        if path:
            return path
    return None


def chromium_driver():
    """A selenium Chrome driver on the system Chromium; skips (or fails under CI=true) without one."""
    browser = _find("chromium", "chromium-browser", "google-chrome")
    driver_path = _find("chromedriver", "chromium-driver")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:  # pragma: no cover - selenium is a test dependency
        browser = None
    if browser is None or driver_path is None:
        message = f"no Chromium found ({INSTALL_HINT})"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"the browser test must run under CI: {message}")
        pytest.skip(message)
    options = webdriver.ChromeOptions()
    for argument in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1280,1600",
                     "--allow-file-access-from-files"):
        options.add_argument(argument)
    options.binary_location = browser
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(driver_path), options=options)


CANVAS_INK = """
var c = document.getElementById('viewer');
var p = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
var background = [p[0], p[1], p[2]], ink = 0;
for (var i = 0; i < p.length; i += 4) {
  if (Math.abs(p[i] - background[0]) + Math.abs(p[i + 1] - background[1])
      + Math.abs(p[i + 2] - background[2]) > 30) ink++;
}
return [c.width, c.height, ink];
"""

IMAGES = """
return Array.from(document.images).map(function (im) { return [im.alt, im.complete, im.naturalWidth]; });
"""


#: Each figure's id, its width and the width of the figure grid it sits in (CSS pixels, as laid out).
FIGURE_WIDTHS = """
return Array.from(document.querySelectorAll('figure')).map(function (f) {
  return [f.id, f.getBoundingClientRect().width, f.parentElement.getBoundingClientRect().width];
});
"""


def check_page(driver, page: Path, screenshot: Path) -> dict:
    """Open ``page``; return console errors, image states, canvas ink, the text as shown, the
    section headings, the figures' widths, and save a screenshot."""
    driver.get(page.resolve().as_uri())
    # the viewer draws when its script runs; on a loaded machine the first read can come before
    # that paint is readable: read again for up to 5 s (a viewer that never draws still fails)
    deadline = time.monotonic() + 5.0
    width, height, ink = driver.execute_script(CANVAS_INK)
    while ink == 0 and time.monotonic() < deadline:
        time.sleep(0.25)
        width, height, ink = driver.execute_script(CANVAS_INK)
    images = driver.execute_script(IMAGES)
    errors = [entry for entry in driver.get_log("browser") if entry.get("level") == "SEVERE"]
    screenshot.parent.mkdir(parents=True, exist_ok=True)
    driver.save_screenshot(str(screenshot))
    text = driver.execute_script("return document.body.innerText;")
    headings = driver.execute_script("return Array.from(document.querySelectorAll('h2')).map(h => h.innerText);")
    figures = driver.execute_script(FIGURE_WIDTHS)
    return {"errors": errors, "images": images, "canvas": (width, height, ink), "text": text,
            "headings": headings, "figures": figures}
