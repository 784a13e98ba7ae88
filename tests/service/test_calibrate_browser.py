"""The viewer's Calibrate mode in a real headless Chromium against a real uvicorn server.

A frame of a known lens (tapes laid on a tiled floor, tape_frames.py) is calibrated by clicking its
true mark pixels, zoomed in with the wheel as a user would; the saved camera is compared with the
true lens and with what `fishloc calibrate` makes of the page's exported marks. Bad marks, frames and
masks must each be explained in the page with the route's own message, and leave the registry as
it was. The page's JavaScript pixel -> floor geometry is compared with fisheye/.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np
import pytest
from calibrate_page import (
    cal_state,
    choose_tool,
    click_mark,
    click_pixel,
    client_of,
    edit_mark,
    import_marks,
    open_calibrate,
    page_errors,
    settled,
    type_into,
    upload_frame,
    zoom_in_at,
)
from calibrate_scene import (
    FOUR_TAPES,
    GUESS,
    OPTIONS,
    RULERS,
    TRUE,
    fit_body,
    floor_error_at_m,
    registry_camera,
    route_refusal,
)
from service_frames import encode
from service_live_server import LiveServer
from tape_frames import TapeFrame, tape_frame
from viewer_browser import chromium_driver, save_screenshot, wait_for

from fisheye import camera_from_dict, camera_to_dict, load_camera
from fisheye.ruler_marks import marks_to_csv, parse_marks_csv, simulate_ruler_marks
from models import DEFAULT_MODEL_PATH
from service.cli import main


@pytest.fixture(scope="module")
def driver() -> Iterator[Any]:
    with chromium_driver() as chromium:
        yield chromium


@pytest.fixture(scope="module")
def frame() -> TapeFrame:
    return tape_frame(TRUE, [azimuth for azimuth, _ in RULERS.values()], list(range(1, 9)))


@pytest.fixture(scope="module")
def frame_path(frame: TapeFrame, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("frames") / "tapes.png"
    path.write_bytes(encode(frame.bgr, ".png"))
    return path


@pytest.fixture
def server(settings_for: Any) -> Iterator[LiveServer]:
    with LiveServer(settings_for()) as live:
        assert httpx.put(f"{live.url}/v1/cameras/tape", json=GUESS).status_code == 201
        yield live


def test_calibrating_a_rendered_frame_by_clicking_its_marks(
    driver: Any, server: LiveServer, frame: TapeFrame, frame_path: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from selenium.webdriver.common.by import By

    open_calibrate(driver, server.url, "tape")
    state = upload_frame(driver, frame_path)
    assert state["frame"] == {"width": 1600, "height": 1200}
    assert state["error"] == "no marks yet: click the nadir, then marks along a tape"
    choose_tool(driver, "nadir")
    click_mark(driver, tuple(frame.nadir_px))
    choose_tool(driver, "mark")
    for r, (ruler, (_, distances)) in enumerate(RULERS.items()):
        type_into(driver, "cal-ruler", ruler)
        type_into(driver, "cal-distance", str(distances[0]))
        type_into(driver, "cal-step", str(distances[1] - distances[0]))
        for distance in distances:
            state = click_mark(driver, tuple(frame.marks_px[r, distance - 1]))
    assert page_errors(driver) == []
    marks = state["marks"]
    assert len(marks) == 1 + sum(len(d) for _, d in RULERS.values())
    assert [m["distance_m"] for m in marks[:4]] == [0, 1, 2, 3] and marks[1]["ruler"] == "east"
    truth = np.concatenate([[frame.nadir_px]] + [frame.marks_px[r, np.array(d) - 1]
                                                   for r, (_, d) in enumerate(RULERS.values())])
    clicked = np.array([[m["u"], m["v"]] for m in marks])
    assert np.abs(clicked - truth).max() < 0.1  # 16× zoom: a screen pixel is a sixteenth of a frame pixel

    # The fit, after every click: residuals at the marks, the RMS, rings and one line per tape.
    fit = state["fit"]
    assert fit is not None and state["error"] == ""
    assert fit["rms_m"] < 0.005 and fit["rms_px"] < 0.1
    rms = f"RMS {fit['rms_m'] * 100:.2f} cm, {fit['rms_px']:.2f} px over {len(marks)} marks"
    assert state["rms"].startswith(rms)
    classes = driver.execute_script(
        "return [...document.querySelectorAll('#cal-frame g.mark')].map((g) => g.getAttribute('class'))")
    assert len(classes) == len(marks) - 1 and all("good" in c.split() for c in classes)
    tapes = driver.execute_script("return [...document.querySelectorAll('#cal-frame polyline.tape')].map("
                                  "(p) => [p.dataset.ruler, Number(p.dataset.azimuthDeg)])")
    assert sorted(name for name, _ in tapes) == sorted(RULERS)
    for name, azimuth in tapes:
        assert (azimuth - RULERS[name][0] + 180) % 360 - 180 == pytest.approx(0, abs=0.2)
    assert driver.find_elements(By.CSS_SELECTOR, "#cal-frame polyline.ring")
    assert state["notes"], "the fit's notes are listed"

    # Nothing reaches the registry before Save.
    assert registry_camera(server) == GUESS
    assert state["unsaved"]
    driver.find_element(By.ID, "cal-save").click()
    wait_for(lambda: cal_state(driver)["saves"] == 1, "the save")
    saved = registry_camera(server)
    assert saved["site_pose"] == GUESS["site_pose"]  # where the camera stands is not the lens's business
    assert saved["max_view_pixels"] == GUESS["max_view_pixels"]  # nor its own view budget
    assert saved["second_look_pixels"] == GUESS["second_look_pixels"]  # nor its second look
    assert saved["longest_person_ratio"] == GUESS["longest_person_ratio"]  # nor its bound on people
    camera = load_camera(saved)
    assert floor_error_at_m(camera, 8.0) < 0.02
    assert floor_error_at_m(camera, 5.0) < 0.01

    # The page's marks.csv through `fishloc calibrate` gives the same camera.
    driver.find_element(By.ID, "cal-export").click()
    exported = wait_for(lambda: cal_state(driver)["exported"], "the export")
    assert len(parse_marks_csv(exported)) == len(marks)
    marks_csv = tmp_path / "marks.csv"
    marks_csv.write_text(exported, encoding="utf-8")
    output = tmp_path / "tape.yaml"
    assert main(["calibrate", "--marks", str(marks_csv), "--altitude", "3.0", "--image-size", "1600", "1200",
                 "--coefficients", "3", "--fit-principal-point", "-o", str(output)]) == 0
    cli = camera_to_dict(load_camera(output))
    for key in ("image_size", "altitude_m"):
        assert saved[key] == cli[key]
    for key in ("principal_point", "focal_px", "kb"):
        np.testing.assert_allclose(saved[key], cli[key], rtol=1e-9, atol=1e-9)

    # Check: a floor point's position and distance by the saved calibration.
    choose_tool(driver, "check")
    target = TRUE.floor_to_pixels(np.array([[5.0, -3.0]]))[0]
    zoom_in_at(driver, (float(target[0]), float(target[1])))
    click_pixel(driver, (float(target[0]), float(target[1])))
    check = wait_for(lambda: cal_state(driver)["checks"], "the check")[-1]
    want = camera.pixels_to_floor(np.array([[check["u"], check["v"]]]))[0]
    np.testing.assert_allclose(check["xy"], want, rtol=0, atol=0.001)
    np.testing.assert_allclose(check["xy"], [5.0, -3.0], atol=0.02)
    text = cal_state(driver)["check"]
    assert f"floor ({check['xy'][0]:.3f}, {check['xy'][1]:.3f}) m" in text
    assert f"{math.hypot(*check['xy']):.3f} m from the nadir" in text
    driver.find_element(By.ID, "cal-whole").click()
    save_screenshot(driver, "viewer-calibrate.png", capsys)
    assert page_errors(driver) == []


def test_marks_are_moved_relabelled_deleted_and_imported(
    driver: Any, server: LiveServer, frame_path: Path, tmp_path: Path,
) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.action_builder import ActionBuilder
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    open_calibrate(driver, server.url, "tape")
    upload_frame(driver, frame_path)
    simulated = FOUR_TAPES
    state = import_marks(driver, tmp_path, marks_to_csv(simulated))
    assert len(state["marks"]) == len(simulated) and state["fit"] is not None
    np.testing.assert_allclose([[m["u"], m["v"]] for m in state["marks"]], simulated.uv_px, atol=1e-9)
    rms_before = state["fit"]["rms_m"]

    # Drag mark 5 (4 m along the east tape) 60 screen px across the tape: it moves, and its
    # residual shows it.
    driver.find_element(By.ID, "cal-whole").click()
    moved = state["marks"][4]
    x, y = client_of(driver, (moved["u"], moved["v"]))
    drag = ActionBuilder(driver)
    drag.pointer_action.move_to_location(round(x), round(y)).pointer_down()
    drag.pointer_action.move_to_location(round(x), round(y) + 30)
    drag.pointer_action.move_to_location(round(x), round(y) + 60).pointer_up()
    drag.perform()
    state = wait_for(lambda: (s := settled(driver))["marks"][4]["v"] > moved["v"] + 50 and s, "the drag")
    assert len(state["marks"]) == len(simulated)
    assert state["fit"]["rms_m"] > rms_before
    assert state["fit"]["marks"][4]["err_m"] > 0.1
    mark_class = driver.execute_script(
        "return document.querySelector(`#cal-frame g[data-mark-id='${arguments[0]}']`).getAttribute('class')",
        moved["id"])
    assert "bad" in mark_class.split()

    # Selected by the drag, it goes with the Delete key.
    ActionChains(driver).send_keys(Keys.DELETE).perform()
    state = wait_for(lambda: len((s := settled(driver))["marks"]) == len(simulated) - 1 and s, "the deletion")
    assert moved["id"] not in [m["id"] for m in state["marks"]]
    assert state["fit"]["rms_m"] < 0.002

    # Relabel mark 2 in the table, delete mark 3 with its button.
    state = edit_mark(driver, 1, "ruler", "tape-b")
    assert state["marks"][1]["ruler"] == "tape-b"
    gone = state["marks"][2]["id"]
    driver.find_element(By.CSS_SELECTOR, f'#cal-marks button.delete[data-mark-id="{gone}"]').click()
    state = wait_for(lambda: len((s := settled(driver))["marks"]) == len(simulated) - 2 and s, "the deletion")
    # A mark given its floor position (x, y): the distance follows.
    state = edit_mark(driver, 3, "x_m", "3.5")
    state = edit_mark(driver, 3, "y_m", "1.2")
    assert state["marks"][3]["distance_m"] == pytest.approx(math.hypot(3.5, 1.2), abs=1e-12)

    # The export is the marks.csv of what the page holds; an unreadable file is refused.
    driver.find_element(By.ID, "cal-export").click()
    exported = parse_marks_csv(wait_for(lambda: cal_state(driver)["exported"], "the export"))
    assert exported.ruler[1] == "tape-b" and len(exported) == len(simulated) - 2
    np.testing.assert_allclose(exported.xy_m[3], [3.5, 1.2])
    state = import_marks(driver, tmp_path, "ruler,u,v,distance_m\neast,,600,1\n", "broken.csv")
    assert state["statusIsError"] and state["status"] == "broken.csv line 2: u and v are required"
    assert len(state["marks"]) == len(simulated) - 2  # unchanged

    # The page reads a marks.csv as `fishloc calibrate` does: comments, quoted labels, x, y alone.
    (u0, v0), (u1, v1), (u2, v2) = simulated.uv_px[:3]
    text = ("# the nadir, a label with a comma, a mark given by its floor position\n"
            "ruler, u, v, distance_m, x_m, y_m\n"
            f"nadir,{u0},{v0},0,,\n"
            f'"east, tape 1",{u1},{v1},1.0,,\n'
            "\n"
            f"east,{u2},{v2},,2.0,0.1\n")
    import_marks(driver, tmp_path, text, "tricky.csv")
    python = parse_marks_csv(text)
    page = cal_state(driver)["marks"]
    assert [m["ruler"] for m in page] == list(python.ruler)
    np.testing.assert_allclose([[m["u"], m["v"], m["distance_m"]] for m in page],
                               np.column_stack([python.uv_px, python.distance_m]), rtol=0, atol=1e-12)
    assert [[m["x_m"], m["y_m"]] for m in page] == [[None, None], [None, None], [2.0, 0.1]]
    assert registry_camera(server) == GUESS
    assert page_errors(driver) == []


def test_bad_input_is_explained_and_nothing_is_saved(
    driver: Any, server: LiveServer, frame_path: Path, tmp_path: Path,
) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import Select

    open_calibrate(driver, server.url, "tape")
    upload_frame(driver, frame_path)

    def refused(state: dict[str, Any], code_words: str) -> None:
        message = route_refusal(server, fit_body(state))
        assert state["fit"] is None and state["error"] == message, (state["error"], message)
        assert code_words in message
        assert registry_camera(server) == GUESS

    def warnings() -> list[list[str]]:
        found: list[list[str]] = driver.execute_script(
            "return [...document.querySelectorAll('#cal-notes li.warning')].map((li) => [li.dataset.code, "
            "li.textContent])")
        return found

    def route_warnings(state: dict[str, Any], **options: Any) -> list[list[str]]:
        body = fit_body(state)
        body["options"] = {**body["options"], **options}
        answer = httpx.post(f"{server.url}/v1/calibrations/fit", json=body)
        assert answer.status_code == 200, answer.text
        return [[n["code"], n["message"]] for n in answer.json()["notes"] if n["level"] == "warning"]

    # Marks that stay near the nadir fit, with a warning to reach farther out; so does a tilt that
    # such marks cannot pin down.
    near = simulate_ruler_marks(TRUE, [10.0, 100.0, 190.0, 280.0], [0.5, 1.0, 1.5, 2.0])
    state = import_marks(driver, tmp_path, marks_to_csv(near), "near.csv")
    assert state["fit"] is not None
    assert warnings() == route_warnings(state) and [code for code, _ in warnings()] == ["marks_short"]
    driver.find_element(By.ID, "cal-fit-tilt").click()
    state = settled(driver)
    assert warnings() == route_warnings(state, fit_tilt=True)
    assert {code for code, _ in warnings()} == {"marks_short", "tilt_undetermined"}
    driver.find_element(By.ID, "cal-fit-tilt").click()
    settled(driver)

    # Fewer distinct distances than coefficients.
    short = simulate_ruler_marks(TRUE, [10.0, 100.0], [1.0])
    refused(import_marks(driver, tmp_path, marks_to_csv(short), "short.csv"), "coefficients")
    Select(driver.find_element(By.ID, "cal-coefficients")).select_by_value("1")
    assert settled(driver)["fit"] is not None
    Select(driver.find_element(By.ID, "cal-coefficients")).select_by_value("3")
    settled(driver)
    # Marks on one radius only, with the principal point fitted.
    one = simulate_ruler_marks(TRUE, [10.0], np.arange(1.0, 8.001, 1.0))
    refused(import_marks(driver, tmp_path, marks_to_csv(one), "one.csv"), "direction")
    # A distance of 0 typed for a mark away from the nadir.
    import_marks(driver, tmp_path, marks_to_csv(FOUR_TAPES), "four.csv")
    refused(edit_mark(driver, 6, "distance_m", "0"), "distance 0")
    # A farther mark nearer the nadir in the frame than a nearer one: no lens does that.
    import_marks(driver, tmp_path, marks_to_csv(FOUR_TAPES), "four.csv")
    refused(edit_mark(driver, 2, "distance_m", "6.5"), "6.5")
    # The registry still has the guess, and the page says the change is not saved.
    assert cal_state(driver)["unsaved"]

    # A frame of another aspect ratio than the camera's image size.
    other = tmp_path / "square.png"
    other.write_bytes(encode(np.zeros((600, 600, 3), np.uint8), ".png"))
    state = upload_frame(driver, other)
    assert state["frame"] == {"width": 600, "height": 600}
    refused(state, "aspect ratio")

    # A self-intersecting mask: flagged while drawn, refused by the service on Save.
    upload_frame(driver, frame_path)
    while driver.find_elements(By.CSS_SELECTOR, "#cal-marks button.delete"):
        driver.find_element(By.CSS_SELECTOR, "#cal-marks button.delete").click()
        settled(driver)
    choose_tool(driver, "mask")
    driver.find_element(By.ID, "cal-whole").click()
    for corner in ((300, 300), (500, 500), (500, 300), (300, 500)):  # a bow tie
        click_pixel(driver, corner)
    wait_for(lambda: "drawing: 4 corners" in cal_state(driver)["masksListed"], "the corners")
    ActionChains(driver).send_keys(Keys.ENTER).perform()
    state = wait_for(lambda: (s := cal_state(driver))["masks"] and s, "the mask")
    assert state["masksListed"][0].startswith("mask 1 crosses itself (edges 1 and 3)")
    driver.find_element(By.ID, "cal-save").click()
    wait_for(lambda: cal_state(driver)["statusIsError"], "the refusal")
    record = dict(GUESS, masks_px=state["masks"])  # the frame is at the image size
    response = httpx.put(f"{server.url}/v1/cameras/tape", json=record)
    assert response.status_code == 422
    assert cal_state(driver)["status"] == response.json()["error"]["message"]
    assert cal_state(driver)["saves"] == 0 and registry_camera(server) == GUESS


def test_masks_and_marks_on_a_smaller_frame_are_saved_at_the_image_size_with_the_token(
    driver: Any, settings_for: Any, frame: TapeFrame, tmp_path: Path,
) -> None:
    from selenium.webdriver.common.by import By

    token = "calibration-token"
    with LiveServer(settings_for(api_token=token)) as server:
        auth = {"Authorization": f"Bearer {token}"}
        assert httpx.put(f"{server.url}/v1/cameras/tape", json=GUESS, headers=auth).status_code == 201
        # The camera sends half-size frames: the page opens on its latest one.
        half = encode(cv2.resize(frame.bgr, (800, 600), interpolation=cv2.INTER_AREA), ".png")
        sent = httpx.post(f"{server.url}/v1/cameras/tape/detect", content=half,
                          headers={"content-type": "image/png"})
        assert sent.status_code == 200, sent.text
        open_calibrate(driver, server.url, "tape")
        wait_for(lambda: cal_state(driver)["frame"], "the latest frame")
        assert cal_state(driver)["frame"] == {"width": 800, "height": 600}
        assert driver.find_element(By.ID, "cal-frame-info").text.startswith("latest frame #")

        # Marks taken at the image size land on the half-size frame, and fit as they were taken.
        simulated = FOUR_TAPES
        state = import_marks(driver, tmp_path, marks_to_csv(simulated))
        on_frame = [[m["u"], m["v"]] for m in state["marks"]]
        np.testing.assert_allclose(on_frame, (simulated.uv_px + 0.5) / 2 - 0.5, rtol=0, atol=1e-9)
        assert "marks scaled to 1600×1200 px" in driver.find_element(By.ID, "cal-frame-info").text
        body = {"altitude_m": 3.0, "image_size": [1600, 1200], "options": OPTIONS,
                "marks": [{"ruler": r, "u": float(u), "v": float(v), "distance_m": float(d)} for r, (u, v), d
                          in zip(simulated.ruler, simulated.uv_px, simulated.distance_m, strict=True)]}
        direct = httpx.post(f"{server.url}/v1/calibrations/fit", json=body)
        assert direct.status_code == 200, direct.text
        for key in ("principal_point", "focal_px", "kb"):
            np.testing.assert_allclose(state["fit"]["camera"][key], direct.json()["camera"][key], rtol=1e-9)

        # A mask of four corners, closed by clicking the first one again.
        choose_tool(driver, "mask")
        driver.find_element(By.ID, "cal-whole").click()
        corners = [(100.0, 80.0), (260.0, 90.0), (250.0, 170.0), (110.0, 160.0)]
        for corner in [*corners, corners[0]]:
            click_pixel(driver, corner)
        state = wait_for(lambda: (s := cal_state(driver))["masks"] and s, "the mask")
        drawn = np.array(state["masks"][0])
        np.testing.assert_allclose(drawn, corners, atol=1.0)  # whole frame: a screen pixel is ~1.4 frame px
        assert state["masksListed"] == ["mask 1: 4 corners ✕"]

        # Without the token the service refuses, and says so; with it the camera is saved.
        driver.find_element(By.ID, "cal-save").click()
        wait_for(lambda: cal_state(driver)["statusIsError"], "the refusal")
        assert cal_state(driver)["status"] == "registry writes need 'Authorization: Bearer <token>'"
        assert registry_camera(server) == GUESS
        refusals = page_errors(driver)  # the browser logs the refused request itself
        assert len(refusals) == 1 and "/v1/cameras/tape" in refusals[0] and "401" in refusals[0]
        type_into(driver, "cal-token", token)
        driver.find_element(By.ID, "cal-save").click()
        wait_for(lambda: cal_state(driver)["saves"] == 1, "the save")
        saved = registry_camera(server)
        np.testing.assert_allclose(saved["masks_px"][0], (drawn + 0.5) * 2 - 0.5, rtol=0, atol=1e-9)
        for key in ("principal_point", "focal_px", "kb"):
            np.testing.assert_allclose(saved[key], direct.json()["camera"][key], rtol=1e-9)
        assert saved["image_size"] == [1600, 1200] and saved["site_pose"] == GUESS["site_pose"]

        # Opened again, the page draws the saved mask on the frame.
        open_calibrate(driver, server.url, "tape")
        wait_for(lambda: cal_state(driver)["frame"], "the latest frame")
        state = settled(driver)
        np.testing.assert_allclose(state["masks"][0], drawn, rtol=0, atol=1e-9)
        assert len(driver.find_elements(By.CSS_SELECTOR, "#cal-frame polygon.mask")) == 1
        assert page_errors(driver) == []


def test_a_tilted_camera_is_fitted_and_checked_with_its_tilt(
    driver: Any, server: LiveServer, tmp_path: Path,
) -> None:
    from selenium.webdriver.common.by import By

    tilted = camera_from_dict(dict(camera_to_dict(TRUE), tilt_deg=[3.0, -2.0]))
    path = tmp_path / "tilted.png"
    azimuths = [0.0, 60.0, 120.0, 180.0, 240.0, 300.0]
    path.write_bytes(encode(tape_frame(tilted, azimuths, [2, 4, 6, 8]).bgr, ".png"))
    open_calibrate(driver, server.url, "tape")
    upload_frame(driver, path)
    marks = simulate_ruler_marks(tilted, azimuths, np.arange(1.0, 8.001, 1.0))
    level = import_marks(driver, tmp_path, marks_to_csv(marks))
    driver.find_element(By.ID, "cal-fit-tilt").click()
    state = settled(driver)
    assert state["fit"]["rms_m"] < level["fit"]["rms_m"] / 10
    np.testing.assert_allclose(state["fit"]["camera"]["tilt_deg"], [3.0, -2.0], atol=0.05)
    driver.find_element(By.ID, "cal-save").click()
    wait_for(lambda: cal_state(driver)["saves"] == 1, "the save")
    saved = load_camera(registry_camera(server))
    np.testing.assert_allclose(saved.tilt_deg, [3.0, -2.0], atol=0.05)

    choose_tool(driver, "check")
    target = tilted.floor_to_pixels(np.array([[6.0, 2.0]]))[0]
    zoom_in_at(driver, (float(target[0]), float(target[1])))
    click_pixel(driver, (float(target[0]), float(target[1])))
    check = wait_for(lambda: cal_state(driver)["checks"], "the check")[-1]
    np.testing.assert_allclose(check["xy"], saved.pixels_to_floor(np.array([[check["u"], check["v"]]]))[0],
                               rtol=0, atol=0.001)
    np.testing.assert_allclose(check["xy"], [6.0, 2.0], atol=0.02)
    assert page_errors(driver) == []


def test_a_camera_not_in_the_registry_is_made_by_the_calibration(
    driver: Any, server: LiveServer, frame_path: Path, tmp_path: Path,
) -> None:
    from selenium.webdriver.common.by import By

    open_calibrate(driver, server.url, "new-cam")
    assert httpx.get(f"{server.url}/v1/cameras/new-cam").status_code == 404
    state = upload_frame(driver, frame_path)
    assert state["camera"] is None
    assert state["error"] == "no marks yet: click the nadir, then marks along a tape"
    size = [driver.find_element(By.ID, f"cal-{side}").get_attribute("value") for side in ("width", "height")]
    assert size == ["1600", "1200"]  # the frame's, with no camera to take it from
    import_marks(driver, tmp_path, marks_to_csv(FOUR_TAPES))
    assert settled(driver)["error"] == "enter the altitude of the lens above the floor (m, > 0)"
    type_into(driver, "cal-altitude", "3")
    driver.find_element(By.ID, "cal-rms").click()  # the altitude is committed when it loses the focus
    state = wait_for(lambda: (s := settled(driver))["fit"] and s, "the fit")
    driver.find_element(By.ID, "cal-save").click()
    wait_for(lambda: cal_state(driver)["saves"] == 1, "the save")
    saved = httpx.get(f"{server.url}/v1/cameras/new-cam").json()
    assert {key: saved[key] for key in state["fit"]["camera"]} == state["fit"]["camera"]
    assert saved["id"] == "new-cam" and "site_pose" not in saved
    assert floor_error_at_m(load_camera(saved), 8.0) < 0.01
    assert "new-cam" in [camera["id"] for camera in httpx.get(f"{server.url}/v1/cameras").json()["cameras"]]


def test_the_page_sets_a_camera_view_budget(driver: Any, settings_for: Any) -> None:
    # With a planned model the page shows the camera's view and the budget it was planned within;
    # the budget typed in is saved with the camera, and emptied, the server's applies again.
    from selenium.webdriver.common.by import By

    def shown() -> str:
        return str(driver.execute_script("return document.getElementById('cal-view').textContent"))

    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH)) as live:
        no_look = {key: value for key, value in GUESS.items() if key != "second_look_pixels"}
        assert httpx.put(f"{live.url}/v1/cameras/tape", json=no_look).status_code == 201
        open_calibrate(driver, live.url, "tape")
        wait_for(lambda: "view: 2band, " in shown(), "the camera's view")  # 2 M px: no nadir view
        assert "of this camera's 2,000,000; its people ask for 2,052,096 px" in shown()
        assert driver.execute_script("return document.getElementById('cal-view-pixels').value") == "2000000"
        type_into(driver, "cal-view-pixels", "12.5")
        driver.find_element(By.ID, "cal-save").click()
        wait_for(lambda: "whole number of px" in cal_state(driver)["status"], "the refusal")
        assert cal_state(driver)["saves"] == 0
        type_into(driver, "cal-view-pixels", "")
        driver.find_element(By.ID, "cal-save").click()
        wait_for(lambda: cal_state(driver)["saves"] == 1, "the save")
        wait_for(lambda: "1band+nadir" in shown(), "the server's view")
        assert "the server's 900,000; its people ask for" in shown()
        saved = httpx.get(f"{live.url}/v1/cameras/tape").json()
        assert "max_view_pixels" not in saved and saved["view"]["budget"]["source"] == "server"
        type_into(driver, "cal-view-pixels", "3000000")
        driver.find_element(By.ID, "cal-save").click()
        wait_for(lambda: cal_state(driver)["saves"] == 2, "the second save")
        wait_for(lambda: shown() == "view: 2band+nadir, 2,052,096 px of this camera's 3,000,000",
                 "the camera's whole view")
        assert httpx.get(f"{live.url}/v1/cameras/tape").json()["max_view_pixels"] == 3_000_000
        assert page_errors(driver) == []
