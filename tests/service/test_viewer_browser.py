"""The web viewer in a real headless Chromium against a real uvicorn server on a loopback port.

What the page draws (box polygons, foot points, the people table, the floor and site maps) is read
back from its DOM and compared with the API's answer for the same frame; its JavaScript projection
of floor points is compared with `FisheyeCamera.floor_to_pixels`. The model is the plumbing test
double (deterministic detections); the shipped default model and sample frames are used too once
they are there. Screenshots go to artifacts/ (CI keeps them).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from service_frames import encode, person_frame
from service_live_server import LiveServer
from viewer_browser import chromium_driver, console_errors, save_screenshot, unavailable, wait_for

from fisheye import FisheyeCamera, camera_to_dict
from models import DEFAULT_MODEL_PATH
from service.core.config import Settings

JPEG = {"content-type": "image/jpeg"}
SAMPLES_DIR = Path(__file__).resolve().parents[2] / "samples"

PAGE_STATE_JS = """
const all = (selector) => [...document.querySelectorAll(selector)];
const number = (value) => (value === undefined ? null : Number(value));
const shown = window.fishlocViewer.state.shown;
return {
  shown: document.body.dataset.shown || null,
  result: shown ? shown.result : null,
  boxes: all('#frame polygon.box').map(
    (p) => ({index: Number(p.dataset.index), points: p.getAttribute('points')})),
  feet: all('#frame circle.foot').map((c) => [Number(c.getAttribute('cx')), Number(c.getAttribute('cy'))]),
  rows: all('#people tbody tr').map((r) => ({
    camera: r.dataset.camera, index: Number(r.dataset.index), x: number(r.dataset.x),
    y: number(r.dataset.y), position: r.querySelector('.position').textContent})),
  people: all(arguments[0] + ' circle.person').map((c) => ({
    camera: c.dataset.camera, index: Number(c.dataset.index), x: Number(c.dataset.x),
    y: Number(c.dataset.y), cx: Number(c.getAttribute('cx')), cy: Number(c.getAttribute('cy'))})),
};
"""


def test_a_missing_browser_skips_here_but_fails_in_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="cannot run in CI: no chromium"):
        unavailable("no chromium")
    monkeypatch.delenv("CI")
    with pytest.raises(pytest.skip.Exception, match="no chromium"):
        unavailable("no chromium")


@pytest.fixture(scope="module")
def driver() -> Iterator[Any]:
    with chromium_driver() as chromium:
        yield chromium


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory, double_model_path: Path) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("viewer")
    settings = Settings(model=double_model_path, database=str(folder / "cameras.db"), http_port=0,
                        grpc_port=-1, threads=1)
    with LiveServer(settings) as live:
        yield live


def page_state(driver: Any, map_selector: str = "#floor-map") -> dict[str, Any]:
    state: dict[str, Any] = driver.execute_script(PAGE_STATE_JS, map_selector)
    return state


def parse_points(text: str) -> list[list[float]]:
    return [[float(v) for v in pair.split(",")] for pair in text.split()]


def open_page(driver: Any, url: str) -> None:
    """Load the page and wait until it has drawn its first view; fail at once on a page error."""
    driver.get("about:blank")  # a URL differing only in its #fragment would not reload the page
    driver.get(url)

    def ready() -> bool:
        errors = console_errors(driver)
        assert errors == [], f"the page logged errors: {errors}"
        return bool(driver.execute_script("return document.body.dataset.state") == "ready")

    wait_for(ready, "the page")


def upload(driver: Any, path: Path) -> dict[str, Any]:
    """Upload `path` through the page's file input; the page's state once it has drawn the answer."""
    from selenium.webdriver.common.by import By

    before = driver.execute_script("return window.fishlocViewer.state.uploads")
    driver.find_element(By.ID, "upload").send_keys(str(path))

    def drawn() -> bool:
        status = driver.find_element(By.ID, "status")
        assert "error" not in (status.get_attribute("class") or ""), f"the page says: {status.text}"
        return bool(driver.execute_script("return window.fishlocViewer.state.uploads") == before + 1)

    wait_for(drawn, f"the page to draw the detections of {path.name}")
    return page_state(driver)


def assert_page_matches(page: dict[str, Any], answer: dict[str, Any]) -> None:
    """The drawn frame, table and floor map show exactly the API's detections."""
    detections = answer["detections"]
    assert page["result"]["detections"] == detections
    assert page["result"]["image"] == answer["image"]
    assert [box["index"] for box in page["boxes"]] == list(range(len(detections)))
    for box, det in zip(page["boxes"], detections, strict=True):
        np.testing.assert_allclose(parse_points(box["points"]), det["corners"], rtol=0, atol=1e-9)
    feet = [det["foot_px"] for det in detections if det["foot_px"] is not None]
    np.testing.assert_allclose(np.reshape(page["feet"], (-1, 2)), np.reshape(feet, (-1, 2)), atol=1e-9)
    assert len(page["rows"]) == len(detections)
    for row, det in zip(page["rows"], detections, strict=True):
        if det["position_m"] is None:
            assert row["x"] is None and row["position"] == "–"
        else:
            x, y = det["position_m"]
            assert (row["x"], row["y"]) == pytest.approx((x, y), abs=1e-12)
            assert row["position"] == f"({x:.2f}, {y:.2f})"
    placed = [(i, det["position_m"]) for i, det in enumerate(detections) if det["position_m"] is not None]
    assert [person["index"] for person in page["people"]] == [i for i, _ in placed]
    for person, (_, (x, y)) in zip(page["people"], placed, strict=True):
        assert (person["x"], person["y"]) == pytest.approx((x, y), abs=1e-12)
        assert (person["cx"], person["cy"]) == pytest.approx((x, -y), abs=1e-9)  # map y points up


def detect(server: LiveServer, data: bytes, camera_id: str = "demo", **params: str) -> dict[str, Any]:
    response = httpx.post(f"{server.url}/v1/cameras/{camera_id}/detect", content=data, headers=JPEG,
                          params=params, timeout=30)
    assert response.status_code == 200, response.text
    answer: dict[str, Any] = response.json()
    return answer


def test_uploaded_frame_is_drawn_as_the_api_answers(
    driver: Any, server: LiveServer, demo_camera: FisheyeCamera, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    truth = person_frame(demo_camera, (1.5, -1.1), demo_camera.image_size)
    path = tmp_path / "person.jpg"
    path.write_bytes(encode(truth.bgr))
    open_page(driver, f"{server.url}/#/camera/demo")
    page = upload(driver, path)
    answer = detect(server, path.read_bytes())
    assert len(answer["detections"]) == 2  # the drawn person and the double's constant box A
    np.testing.assert_allclose(answer["detections"][0]["position_m"], truth.floor_xy_m, atol=0.005)
    assert page["result"]["frame_id"] == "person.jpg"
    assert_page_matches(page, answer)
    save_screenshot(driver, "viewer.png", capsys)
    assert console_errors(driver) == []


@pytest.mark.parametrize("resolution_wh", [(2048, 2048), (1024, 1024), (512, 512)])
def test_floor_rings_are_drawn_where_python_projects_them(
    driver: Any, server: LiveServer, demo_camera: FisheyeCamera, tmp_path: Path,
    resolution_wh: tuple[int, int],
) -> None:
    path = tmp_path / "frame.jpg"
    path.write_bytes(encode(person_frame(demo_camera, (0.8, 0.6), resolution_wh, disk_radius_px=8).bgr))
    open_page(driver, f"{server.url}/#/camera/demo")
    upload(driver, path)
    rings = driver.execute_script(
        "return [...document.querySelectorAll('#frame polyline.ring')].map("
        "(p) => [Number(p.dataset.radiusM), p.getAttribute('points')])")
    radii = sorted({radius for radius, _ in rings})
    assert radii[:4] == [1, 2, 3, 4]
    scaled = demo_camera.scaled_to(resolution_wh)
    for radius, points in rings:
        drawn = np.array(parse_points(points))
        phi = 2 * np.pi * np.arange(len(drawn)) / 180  # the ring's samples start on +x, 2° apart
        floor = radius * np.stack([np.cos(phi), np.sin(phi)], axis=1)
        np.testing.assert_allclose(drawn, scaled.floor_to_pixels(floor), rtol=0, atol=1e-6)
    assert console_errors(driver) == []


WIDE_CAMERA = {
    "id": "wide", "altitude_m": 2.7, "image_size": [2000, 1500], "principal_point": [1012.5, 740.25],
    "focal_px": [610.0, 604.0], "kb": [1.0, -0.021, 0.0013, -0.0002, 0.00001], "max_theta_deg": 80,
}
TILTED_CAMERA = dict(WIDE_CAMERA, id="tilted", tilt_deg=[6.0, -3.5])


@pytest.mark.parametrize(("camera_record", "resolution_wh"), [
    ("demo", (2048, 2048)), ("demo", (1024, 1024)), ("demo", (300, 300)),
    (WIDE_CAMERA, (2000, 1500)), (WIDE_CAMERA, (1000, 750)), (WIDE_CAMERA, (640, 480)),
    (TILTED_CAMERA, (2000, 1500)), (TILTED_CAMERA, (1000, 750)),
], ids=["demo-2048", "demo-1024", "demo-300", "wide-2000", "wide-1000", "wide-640", "tilted-2000",
        "tilted-1000"])
def test_javascript_projection_matches_python(
    driver: Any, server: LiveServer, demo_camera: FisheyeCamera, camera_record: str | dict[str, Any],
    resolution_wh: tuple[int, int],
) -> None:
    camera = demo_camera if camera_record == "demo" else FisheyeCamera.model_validate(camera_record)
    open_page(driver, f"{server.url}/#/camera/demo")
    grid = np.linspace(-12.0, 12.0, 9)
    floor = np.concatenate([[[0.0, 0.0], [1.0, 0.0], [0.0, -1.0], [40.0, 3.0], [0.3, 25.0]],
                            np.stack(np.meshgrid(grid, grid), axis=-1).reshape(-1, 2)])
    got = driver.execute_script(
        "return window.fishlocViewer.floorToPixels(arguments[0], arguments[1], arguments[2])",
        camera_to_dict(camera), list(resolution_wh), floor.tolist())
    want = camera.scaled_to(resolution_wh).floor_to_pixels(floor)
    beyond = np.isnan(want[:, 0])
    assert [uv is None for uv in got] == beyond.tolist()
    if camera.id != "demo":
        assert beyond.any()  # θmax cuts the far points off
    drawn = np.array([uv for uv in got if uv is not None]).reshape(-1, 2)
    np.testing.assert_allclose(drawn, want[~beyond], rtol=0, atol=1e-6)


def test_latest_frame_from_another_client_is_shown(
    driver: Any, server: LiveServer, demo_camera: FisheyeCamera,
) -> None:
    from selenium.webdriver.common.by import By

    open_page(driver, f"{server.url}/#/camera/demo")
    driver.find_element(By.ID, "follow").click()
    truth = person_frame(demo_camera, (-2.2, 0.9), (1024, 1024), disk_radius_px=20)
    answer = detect(server, encode(truth.bgr), frame_id="from-rest")
    latest = httpx.get(f"{server.url}/v1/cameras/demo/latest").json()
    assert latest["result"]["frame_id"] == "from-rest"
    wait_for(lambda: page_state(driver)["shown"] == f"demo:latest:{latest['sequence']}", "the latest frame")
    page = page_state(driver)
    assert page["result"]["frame_id"] == "from-rest"
    assert_page_matches(page, answer)
    assert console_errors(driver) == []


def test_site_map_shows_every_posed_camera_and_its_people(
    driver: Any, server: LiveServer, demo_camera: FisheyeCamera, capsys: pytest.CaptureFixture[str],
) -> None:
    from selenium.webdriver.common.by import By

    annex = dict(camera_to_dict(demo_camera), id="annex", site_pose={"x_m": 9.0, "y_m": 2.0, "yaw_deg": 90.0})
    assert httpx.put(f"{server.url}/v1/cameras/annex", json=annex).status_code in (200, 201)
    unposed = dict(camera_to_dict(demo_camera), id="hall")
    unposed.pop("site_pose")
    assert httpx.put(f"{server.url}/v1/cameras/hall", json=unposed).status_code in (200, 201)
    frames = {cid: person_frame(demo_camera, xy, (1024, 1024), 20) for cid, xy in
              (("demo", (1.0, 2.0)), ("annex", (-1.5, 0.5)))}
    answers = {cid: detect(server, encode(frame.bgr), cid) for cid, frame in frames.items()}
    sequences = [httpx.get(f"{server.url}/v1/cameras/{cid}/latest").json()["sequence"] for cid in answers]
    open_page(driver, f"{server.url}/#/site")
    def shown_sequences() -> set[str]:
        return set((page_state(driver, "#site-map")["shown"] or "site:").split(":")[1].split(","))

    wait_for(lambda: shown_sequences() == {str(sequence) for sequence in sequences}, "the site map")
    page = page_state(driver, "#site-map")
    want = {(cid, i): det["site_position_m"] for cid, answer in answers.items()
            for i, det in enumerate(answer["detections"])}
    got = {(person["camera"], person["index"]): [person["x"], person["y"]] for person in page["people"]}
    assert set(got) == set(want)
    for key, xy in want.items():
        assert got[key] == pytest.approx(xy, abs=1e-12)
    # annex turns its floor frame by 90°: its person at floor (-1.5, 0.5) stands at site (8.5, 0.5).
    np.testing.assert_allclose(got[("annex", 0)], [9.0 - 0.5, 2.0 - 1.5], atol=0.01)
    cameras = driver.execute_script(
        "return [...document.querySelectorAll('#site-map g.camera')].map((g) => g.dataset.camera)")
    assert sorted(cameras) == ["annex", "demo"]  # hall has no site pose
    assert len(page["rows"]) == len(want)
    save_screenshot(driver, "viewer-site.png", capsys)

    # "fields of view": the map widens to hold both cameras' circles (θ = min(max_theta, 85°)).
    from selenium.webdriver.support.ui import Select

    def renders() -> int:
        return int(driver.execute_script("return window.fishlocViewer.state.renders"))

    before = renders()
    Select(driver.find_element(By.ID, "site-extent")).select_by_value("fov")
    wait_for(lambda: renders() > before, "the redraw")
    bounds = driver.execute_script("return JSON.parse(document.getElementById('site-map').dataset.bounds)")
    fov_m = demo_camera.altitude_m * math.tan(math.radians(min(demo_camera.theta_max_deg, 85.0)))
    for x, y in ((0.0, 0.0), (9.0, 2.0)):
        assert bounds["xmin"] <= x - fov_m + 1e-9 and bounds["xmax"] >= x + fov_m - 1e-9
        assert bounds["ymin"] <= y - fov_m + 1e-9 and bounds["ymax"] >= y + fov_m - 1e-9
    circles = driver.execute_script("return [...document.querySelectorAll('#site-map circle.fov')]"
                                    ".map((c) => Number(c.getAttribute('r')))")
    assert circles == pytest.approx([fov_m, fov_m], rel=1e-12)
    assert console_errors(driver) == []


def test_sample_frame_is_drawn_as_the_api_answers(
    driver: Any, server: LiveServer, tmp_path_factory: pytest.TempPathFactory,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A shipped sample frame, served by the shipped default model when it is there (else by the test
    double): the page shows what the API answers, however many people that is."""
    samples = sorted(SAMPLES_DIR.glob("*.jpg"))
    if not samples:
        pytest.skip("no sample frames (samples/*.jpg) yet")

    def check(live: LiveServer) -> None:
        open_page(driver, f"{live.url}/#/camera/demo")
        page = upload(driver, samples[0])
        answer = detect(live, samples[0].read_bytes())
        assert math.isfinite(answer["timing_ms"]["total"])
        assert_page_matches(page, answer)
        save_screenshot(driver, "viewer-sample.png", capsys)

    if DEFAULT_MODEL_PATH.is_file():
        folder = tmp_path_factory.mktemp("viewer-default")
        settings = Settings(database=str(folder / "cameras.db"), http_port=0, grpc_port=-1, threads=1)
        with LiveServer(settings) as live:
            check(live)
    else:
        check(server)
    assert console_errors(driver) == []


def test_refused_frame_is_reported_and_other_cameras_open_from_the_list(
    driver: Any, server: LiveServer, demo_camera: FisheyeCamera, tmp_path: Path,
) -> None:
    from selenium.webdriver.common.by import By

    open_page(driver, f"{server.url}/#/camera/demo")
    wide = tmp_path / "wide.jpg"
    wide.write_bytes(encode(np.zeros((300, 600, 3), np.uint8)))  # not the demo camera's aspect ratio
    driver.find_element(By.ID, "upload").send_keys(str(wide))
    status = wait_for(lambda: driver.execute_script(
        "const s = document.getElementById('status'); return s.classList.contains('error') && s.textContent"),
        "the error message")
    refused = httpx.post(f"{server.url}/v1/cameras/demo/detect", content=wide.read_bytes(), headers=JPEG)
    assert refused.status_code == 422 and status == refused.json()["error"]["message"]
    # The browser logs the refused request itself; nothing else went wrong.
    assert all("/detect" in error and "422" in error for error in console_errors(driver))

    other = dict(camera_to_dict(demo_camera), id="lobby")
    assert httpx.put(f"{server.url}/v1/cameras/lobby", json=other).status_code in (200, 201)
    answer = detect(server, encode(person_frame(demo_camera, (0.4, -2.5), (1024, 1024), 20).bgr), "lobby")
    open_page(driver, f"{server.url}/#/camera/demo")
    driver.find_element(By.CSS_SELECTOR, '#camera-list a[data-camera="lobby"]').click()
    wait_for(lambda: (page_state(driver)["shown"] or "").startswith("lobby:latest:"), "the lobby camera")
    assert driver.find_element(By.ID, "camera-title").text.startswith("lobby")
    assert_page_matches(page_state(driver), answer)


@pytest.mark.parametrize(("camera_record", "resolution_wh"), [
    ("demo", (2048, 2048)), ("demo", (512, 512)), (WIDE_CAMERA, (2000, 1500)), (WIDE_CAMERA, (640, 480)),
    (TILTED_CAMERA, (2000, 1500)), (TILTED_CAMERA, (1000, 750)),
], ids=["demo-2048", "demo-512", "wide-2000", "wide-640", "tilted-2000", "tilted-1000"])
def test_javascript_pixels_to_floor_match_python(
    driver: Any, server: LiveServer, demo_camera: FisheyeCamera, camera_record: str | dict[str, Any],
    resolution_wh: tuple[int, int],
) -> None:
    """The Check tool's pixel -> floor (geometry.js) agrees with FisheyeCamera.pixels_to_floor to a
    millimetre wherever Python has a floor point, and has none where Python has none."""
    camera = demo_camera if camera_record == "demo" else FisheyeCamera.model_validate(camera_record)
    open_page(driver, f"{server.url}/#/camera/demo")
    width, height = resolution_wh
    u, v = np.meshgrid(np.linspace(-0.5, width - 0.5, 41), np.linspace(-0.5, height - 0.5, 31))
    pixels = np.concatenate([np.stack([u.ravel(), v.ravel()], axis=1),
                             camera.scaled_to(resolution_wh).floor_to_pixels([[0.0, 0.0], [7.5, -2.0]])])
    got = driver.execute_script(
        "return window.fishlocViewer.pixelsToFloor(arguments[0], arguments[1], arguments[2])",
        camera_to_dict(camera), list(resolution_wh), pixels.tolist())
    want = camera.scaled_to(resolution_wh).pixels_to_floor(pixels)
    missing = np.isnan(want[:, 0])
    assert [xy is None for xy in got] == missing.tolist()
    assert missing.any() and (~missing).sum() > 100
    placed = np.array([xy for xy in got if xy is not None])
    np.testing.assert_allclose(placed, want[~missing], rtol=0, atol=0.001)
    np.testing.assert_allclose(placed[-2:], [[0.0, 0.0], [7.5, -2.0]], atol=1e-6)
