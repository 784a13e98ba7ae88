"""Driving the viewer's Calibrate mode in a real headless Chromium as a user does: wheel-zooming at a
point of the frame, clicking frame pixels, typing into the page, and reading back what it shows."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from viewer_browser import console_errors, wait_for

# The fit route refuses marks that cannot give a lens yet (the page shows why); the browser logs each.
_FIT_REFUSAL = re.compile(r"/v1/calibrations/fit - Failed to load resource: .* status of 4\d\d ")
ZOOM_WHEEL_PX = -960  # one wheel gesture of 960 px zooms in 16×

CLIENT_OF_PIXEL_JS = """
const svg = document.getElementById('cal-frame');
const point = new DOMPoint(arguments[0], arguments[1]).matrixTransform(svg.getScreenCTM());
return [point.x, point.y];
"""

CAL_STATE_JS = """
const cal = window.fishlocViewer.calibrate;
return {
  marks: cal.marks.map((m) => ({...m})), masks: cal.masks, fit: cal.fit, fitError: cal.fitError,
  fitsWanted: cal.fitsWanted, fitsDone: cal.fitsDone, fitting: cal.fitting, saves: cal.saves,
  camera: cal.camera, frame: cal.frame && {width: cal.frame.width, height: cal.frame.height},
  checks: cal.checks, frames: cal.frames, exported: cal.exported ?? null, unsaved: cal.unsaved,
  error: document.getElementById('cal-error').textContent,
  status: document.getElementById('status').textContent,
  statusIsError: document.getElementById('status').classList.contains('error'),
  rms: document.getElementById('cal-rms').textContent,
  notes: [...document.querySelectorAll('#cal-notes li')].map((li) => li.textContent),
  masksListed: [...document.querySelectorAll('#cal-masks li')].map((li) => li.textContent),
  check: document.getElementById('cal-check').textContent,
  screenPerFrame: Number(document.getElementById('cal-frame').getScreenCTM().a),
};
"""


def page_errors(driver: Any) -> list[str]:
    """The page's errors since the last call, but for the fit route's refusals."""
    return [error for error in console_errors(driver) if not _FIT_REFUSAL.search(error)]


def cal_state(driver: Any) -> dict[str, Any]:
    state: dict[str, Any] = driver.execute_script(CAL_STATE_JS)
    return state


def open_calibrate(driver: Any, url: str, camera_id: str) -> None:
    """Load the page on the Calibrate mode of `camera_id`; fail at once on a page error."""
    driver.get("about:blank")
    driver.get_log("browser")  # forget what earlier pages logged
    driver.get(f"{url}/#/calibrate/{camera_id}")

    def ready() -> bool:
        errors = console_errors(driver)
        assert errors == [], f"the page logged errors: {errors}"
        return bool(driver.execute_script("return document.body.dataset.state") == "ready")

    wait_for(ready, "the page")


def settled(driver: Any) -> dict[str, Any]:
    """The Calibrate state once every change has been fitted."""
    def done() -> dict[str, Any] | None:
        state = cal_state(driver)
        return state if not state["fitting"] and state["fitsDone"] == state["fitsWanted"] else None

    return wait_for(done, "the fit")


def upload_frame(driver: Any, path: Path) -> dict[str, Any]:
    from selenium.webdriver.common.by import By

    before = cal_state(driver)["frames"]
    driver.find_element(By.ID, "cal-upload").send_keys(str(path))
    wait_for(lambda: cal_state(driver)["frames"] > before, f"the frame {path.name}")
    return settled(driver)


def choose_tool(driver: Any, tool: str) -> None:
    from selenium.webdriver.common.by import By

    driver.find_element(By.CSS_SELECTOR, f'input[name="cal-tool"][value="{tool}"]').click()


def type_into(driver: Any, element_id: str, text: str) -> None:
    from selenium.webdriver.common.by import By

    field = driver.find_element(By.ID, element_id)
    field.clear()
    field.send_keys(text)


def client_of(driver: Any, uv: tuple[float, float]) -> tuple[float, float]:
    x, y = driver.execute_script(CLIENT_OF_PIXEL_JS, float(uv[0]), float(uv[1]))
    return float(x), float(y)


def zoom_in_at(driver: Any, uv: tuple[float, float]) -> None:
    """Whole frame, then one wheel gesture at the pixel `uv`: 16× closer around it."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
    from selenium.webdriver.common.by import By

    driver.find_element(By.ID, "cal-whole").click()
    whole = cal_state(driver)["screenPerFrame"]
    x, y = client_of(driver, uv)
    origin = ScrollOrigin.from_viewport(round(x), round(y))
    ActionChains(driver).scroll_from_origin(origin, 0, ZOOM_WHEEL_PX).perform()
    wait_for(lambda: cal_state(driver)["screenPerFrame"] > 15.9 * whole, "the zoom")


def click_pixel(driver: Any, uv: tuple[float, float]) -> None:
    """A click on the screen pixel nearest frame pixel `uv` (zoom in first for sub-pixel clicks)."""
    from selenium.webdriver.common.actions.action_builder import ActionBuilder

    x, y = client_of(driver, uv)
    actions = ActionBuilder(driver)
    actions.pointer_action.move_to_location(round(x), round(y)).click()
    actions.perform()


def click_mark(driver: Any, uv: tuple[float, float]) -> dict[str, Any]:
    """Zoom in at `uv`, click it, and return the state once the new mark is fitted."""
    before = len(cal_state(driver)["marks"])
    zoom_in_at(driver, uv)
    click_pixel(driver, uv)
    wait_for(lambda: len(cal_state(driver)["marks"]) == before + 1 or cal_state(driver)["statusIsError"],
             "the mark")
    return settled(driver)


def import_marks(driver: Any, tmp_path: Path, csv_text: str, name: str = "marks.csv") -> dict[str, Any]:
    from selenium.webdriver.common.by import By

    path = tmp_path / name
    path.write_text(csv_text, encoding="utf-8")
    before = cal_state(driver)["fitsWanted"]
    driver.find_element(By.ID, "cal-import").send_keys(str(path))
    wait_for(lambda: cal_state(driver)["fitsWanted"] > before or cal_state(driver)["statusIsError"],
             "the import")
    return settled(driver)


def edit_mark(driver: Any, index: int, field: str, text: str) -> dict[str, Any]:
    """Type `text` into the marks table's `field` of mark `index` (0-based) and commit it."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    mark_id = cal_state(driver)["marks"][index]["id"]
    selector = f'#cal-marks input[data-mark-id="{mark_id}"][data-field="{field}"]'
    field_input = driver.find_element(By.CSS_SELECTOR, selector)
    before = cal_state(driver)["fitsWanted"]
    field_input.send_keys(Keys.CONTROL, "a")  # select the old value (clear() would commit an empty one)
    field_input.send_keys(text, Keys.ENTER)  # Enter commits the change
    wait_for(lambda: cal_state(driver)["fitsWanted"] > before or cal_state(driver)["statusIsError"],
             "the edit")
    return settled(driver)
