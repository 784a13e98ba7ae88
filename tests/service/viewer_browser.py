"""A real headless Chromium (Debian's `chromium` + `chromium-driver`) driven by Selenium.

Outside CI a machine without them skips the browser tests with the reason; in CI (CI=true) their
absence fails the run, so the viewer is never left untested there.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import pytest

from tests.ci_policy import skip_or_fail_in_ci

CHROMIUM_PATHS = ("/usr/bin/chromium", "/usr/bin/chromium-browser")
CHROMEDRIVER_PATHS = ("/usr/bin/chromedriver",)
# Without the networking switches Chromium keeps calling home, which a closed network answers slowly.
CHROMIUM_FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--disable-dev-shm-usage", "--window-size=1400,1000", "--force-device-scale-factor=1",
)
ARTIFACTS_DIR = Path(__file__).resolve().parents[2] / "artifacts"
T = TypeVar("T")


def _first_existing(paths: tuple[str, ...]) -> str | None:
    return next((path for path in paths if Path(path).is_file() and os.access(path, os.X_OK)), None)


def unavailable(reason: str) -> None:
    """Skip (fail in CI) because the browser cannot run here."""
    skip_or_fail_in_ci(reason, f"the viewer's browser test cannot run in CI: {reason}")


@contextmanager
def chromium_driver(extra_flags: tuple[str, ...] = ()) -> Iterator[Any]:
    """A Selenium WebDriver over a headless Chromium with a fresh profile (and `extra_flags`); quit
    on exit."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        unavailable("selenium is not installed (pip install -e '.[dev]')")
    chromium = _first_existing(CHROMIUM_PATHS)
    driver_path = _first_existing(CHROMEDRIVER_PATHS) or shutil.which("chromedriver")
    if chromium is None or driver_path is None:
        unavailable("Debian's chromium and chromium-driver are not installed "
                    "(apt-get install -y chromium chromium-driver)")
    with tempfile.TemporaryDirectory(prefix="fishloc-chromium-") as profile:
        options = webdriver.ChromeOptions()
        options.binary_location = chromium
        for flag in (*CHROMIUM_FLAGS, *extra_flags, f"--user-data-dir={profile}"):
            options.add_argument(flag)
        options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
        driver = webdriver.Chrome(options=options, service=Service(executable_path=driver_path))
        try:
            yield driver
        finally:
            driver.quit()


def wait_for(condition: Callable[[], T | None], what: str, timeout_s: float = 30.0) -> T:
    """Poll `condition` until it returns a truthy value (returned); fail with `what` after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    last: T | None = None
    while time.monotonic() < deadline:
        last = condition()
        if last:
            return last
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what} (last value {last!r})")


# The API answers 404 `no_frame` for a camera that has had no frame yet; the page expects that.
_EXPECTED_ERRORS = re.compile(r"/v1/cameras/[^/ ]+/latest - Failed to load resource: .* 404 \(Not Found\)$")


def console_errors(driver: Any) -> list[str]:
    """Errors the page logged (uncaught exceptions, failed loads) since the last call, but for the
    expected 404 of a camera without a frame."""
    return [entry["message"] for entry in driver.get_log("browser")
            if entry["level"] == "SEVERE" and not _EXPECTED_ERRORS.search(entry["message"])]


def save_screenshot(driver: Any, name: str, capsys: pytest.CaptureFixture[str]) -> Path:
    """Save a screenshot under artifacts/ (a CI artefact) and print its path past pytest's capture."""
    ARTIFACTS_DIR.mkdir(exist_ok=True)
    path = ARTIFACTS_DIR / name
    driver.save_screenshot(str(path))
    with capsys.disabled():
        print(f"\nviewer screenshot: {path}")
    return path
