from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from detector.data.readers import DatasetFormatError, read_dataset, write_dataset
from fisheye import assumed_camera, foot_points, radius_aligned_to_cepdof

FIXTURES = Path(__file__).parent / "fixtures"


def test_fishloc_format_round_trip(toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    source = toy_dataset(count=3)
    frames = read_dataset(source)
    assert len(frames) == 3 and all(len(f) == 3 for f in frames)
    first = frames[0]
    assert first.camera is not None and first.camera.id == "toy" and not first.camera_assumed
    assert first.file_boxes_cxcywha is None and first.file_crowd_cxcywha is None
    assert first.path.exists() and first.split == "seen"
    np.testing.assert_allclose(first.distances_m, np.hypot(*first.locations_m.T))
    copy = source.parent / "copy.json"
    write_dataset(frames, copy)
    again = read_dataset(copy)
    for a, b in zip(frames, again, strict=True):
        np.testing.assert_allclose(a.boxes_cxcywh, b.boxes_cxcywh)
        np.testing.assert_allclose(a.locations_m, b.locations_m)
        assert (a.path, a.image_id, a.scene_id, a.camera) == (b.path, b.image_id, b.scene_id, b.camera)
    assert read_dataset(source.parent)[0].path == first.path  # a folder reads its annotations.json


def test_cepdof_boxes_become_radius_aligned_about_the_frame_centre(tmp_path: Path) -> None:
    centre = (1023.5, 1023.5)
    radius_aligned = np.array([[1400.0, 1300.0, 150.0, 400.0], [600.0, 500.0, 120.0, 300.0]])
    cepdof = radius_aligned_to_cepdof(radius_aligned, centre)
    document = {
        "images": [{"id": "Lunch_1", "file_name": "Lunch_1.jpg", "width": 2048, "height": 2048}],
        "annotations": [{"id": i, "image_id": "Lunch_1", "category_id": 1, "bbox": box.tolist()}
                        for i, box in enumerate(cepdof)],
        "categories": [{"id": 1, "name": "person"}],
    }
    path = tmp_path / "cepdof.json"
    path.write_text(json.dumps(document))
    (frame,) = read_dataset(path)
    assert frame.camera_assumed and frame.camera == assumed_camera(2048, 2048)
    assert frame.principal_point == centre
    np.testing.assert_allclose(frame.boxes_cxcywh, radius_aligned, atol=1e-9)
    assert frame.file_boxes_cxcywha is not None
    np.testing.assert_array_equal(frame.file_boxes_cxcywha, cepdof)  # the file's own, as they were
    # The assumed camera places nobody: positions and distances stay unknown.
    assert np.all(np.isnan(frame.locations_m)) and np.all(np.isnan(frame.distances_m))


# Expected boxes by hand. CEPDOF's h axis is turned clockwise from the image's up direction, so it
# points along (sin a, -cos a); the side nearer the ray from the frame centre becomes the radial h.
CEPDOF_SAMPLE = {  # 2048 x 2048, centre (1023.5, 1023.5)
    "Sample1_000001": (
        [[1023.5, 523.5, 100.0, 300.0],    # above the centre, a = 0: h upright, on the ray
         [1523.5, 1023.5, 80.0, 240.0],    # right of it, a = -90: h horizontal, on the ray
         [1023.5, 1423.5, 200.0, 60.0],    # below it, a = -90: h across the ray, so w is radial
         [1023.5, 1023.5, 150.0, 120.0],   # on the centre: the ray is +u (angle 0), h at 30° is off it
         [723.5, 723.5, 90.0, 270.0]],     # up-left, a = -40: 5° off the ray at -45
        [[1323.5, 723.5, 100.0, 250.0]],   # iscrowd, up-right, a = 50: 5° off the ray at 45
    ),
    "Sample1_000002": ([[1423.5, 1423.5, 110.0, 330.0]], []),  # down-right, a = -45: on the ray
    "Sample1_000003": ([], []),
}
WEPDTOF_SAMPLE = {  # 1080 x 1080, centre (539.5, 539.5)
    "sample_store_000001": (
        [[539.5, 539.5, 70.0, 90.0],       # on the centre, a = -90: h along +u, the ray there
         [239.5, 539.5, 50.0, 160.0],      # left, a = -90: on the ray
         [539.5, 839.5, 60.0, 170.0],      # below, a = 0: on the ray
         [789.5, 539.5, 120.0, 40.0],      # right, a = 0: h across the ray, so w is radial
         [289.5, 789.5, 55.0, 150.0]],     # down-left, a = 45: on the ray
        [],
    ),
}


@pytest.mark.parametrize(("name", "size", "expected"), [
    ("cepdof_sample.json", 2048, CEPDOF_SAMPLE),
    ("wepdtof_sample.json", 1080, WEPDTOF_SAMPLE),
])
def test_cepdof_style_files_read_into_radius_aligned_boxes(
    name: str, size: int, expected: dict[str, tuple[list[list[float]], list[list[float]]]],
) -> None:
    """Made-up files in the layout of the real CEPDOF ones: string image ids, `segmentation`,
    `person_id`, no annotation ids, `bbox` [cx, cy, w, h, angle_deg] with w <= h."""
    frames = read_dataset(FIXTURES / name)
    assert [f.image_id for f in frames] == list(expected)
    centre = ((size - 1) / 2, (size - 1) / 2)
    raw = json.loads((FIXTURES / name).read_text())["annotations"]
    for frame in frames:
        boxes, crowd = expected[str(frame.image_id)]
        assert frame.camera_assumed and frame.camera == assumed_camera(size, size)
        assert frame.principal_point == centre
        mine = [a for a in raw if a["image_id"] == frame.image_id]
        assert frame.file_boxes_cxcywha is not None and frame.file_crowd_cxcywha is not None
        np.testing.assert_array_equal(frame.file_boxes_cxcywha,
                                      np.array([a["bbox"] for a in mine if not a["iscrowd"]]).reshape(-1, 5))
        np.testing.assert_array_equal(frame.file_crowd_cxcywha,
                                      np.array([a["bbox"] for a in mine if a["iscrowd"]]).reshape(-1, 5))
        assert (frame.width, frame.height) == (size, size)
        assert frame.path == FIXTURES / f"{frame.image_id}.jpg"
        np.testing.assert_allclose(frame.boxes_cxcywh, np.array(boxes).reshape(-1, 4), atol=1e-9)
        np.testing.assert_allclose(frame.crowd_cxcywh, np.array(crowd).reshape(-1, 4), atol=1e-9)
        assert np.isnan(frame.locations_m).all() and np.isnan(frame.visible_fraction).all()
        assert frame.bboxes_xywh is not None and np.isnan(frame.bboxes_xywh).all()
        # Boxes on the centre have their foot point there.
        on_centre = np.all(frame.boxes_cxcywh[:, :2] == centre, axis=1)
        np.testing.assert_array_equal(foot_points(frame.boxes_cxcywh[on_centre], centre),
                                      np.tile(centre, (int(on_centre.sum()), 1)))
    assert sum(int(np.all(f.boxes_cxcywh[:, :2] == centre, axis=1).sum()) for f in frames) == 1


def test_frames_without_a_calibration_get_the_assumed_camera_and_do_not_write_it(tmp_path: Path) -> None:
    """DESIGN.md: an ideal equidistant lens whose 180° circle fills the shorter side, 3 m up."""
    path = tmp_path / "wide.json"
    path.write_text(json.dumps({
        "images": [{"id": "w", "file_name": "w.jpg", "width": 1920, "height": 1080}],
        "annotations": [{"image_id": "w", "bbox": [900.0, 300.0, 40.0, 120.0, 10.0]}],
    }))
    (frame,) = read_dataset(path)
    camera = frame.camera
    assert camera is not None and frame.camera_assumed
    assert (camera.id, camera.altitude_m, camera.kb) == ("assumed", 3.0, [1.0])
    assert camera.image_size == (1920, 1080)
    assert camera.principal_point == (959.5, 539.5)
    assert camera.focal_px == pytest.approx((540 / (np.pi / 2),) * 2)
    assert camera.image_circle_radius_px() == pytest.approx(540.0)
    assert np.isnan(frame.distances_m).all() and np.isnan(frame.locations_m).all()
    # Written as a FishLoc file, an assumption is not passed off as a calibration.
    write_dataset([frame], tmp_path / "again.json")
    assert "camera" not in json.loads((tmp_path / "again.json").read_text())["images"][0]


@pytest.mark.parametrize(("content", "message"), [
    ("{not json", "not valid JSON"),
    ('{"annotations": []}', "no 'images' list"),
    ('{"images": [{"id": 1, "file_name": "a.jpg", "width": 8, "height": 8}],'
     ' "annotations": [{"image_id": 1, "bbox": [1, 2, 3, 4]}]}', "neither rotated_box"),
    ('{"images": [{"id": 1, "file_name": "a.jpg", "width": 8, "height": 8, "camera": {}}],'
     ' "annotations": [{"image_id": 1, "rotated_box": [1, 2, 3, 4]}]}', "invalid camera"),
])
def test_bad_files_give_clear_errors(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(DatasetFormatError, match=message):
        read_dataset(path)


def test_frame_without_people(tmp_path: Path) -> None:
    path = tmp_path / "empty.json"
    path.write_text(json.dumps({"images": [{"id": 1, "file_name": "a.jpg", "width": 8, "height": 8}],
                                "annotations": []}))
    (frame,) = read_dataset(path)
    assert frame.boxes_cxcywh.shape == (0, 4) and frame.locations_m.shape == (0, 2)


def test_crowd_boxes_are_kept_apart_and_written_back(tmp_path: Path) -> None:
    document = {
        "images": [{"id": 1, "file_name": "a.jpg", "width": 100, "height": 100}],
        "annotations": [
            {"id": 1, "image_id": 1, "category_id": 1, "rotated_box": [20, 30, 5, 9], "iscrowd": 0},
            {"id": 2, "image_id": 1, "category_id": 1, "rotated_box": [70, 60, 4, 6], "iscrowd": 1},
        ],
    }
    path = tmp_path / "crowd.json"
    path.write_text(json.dumps(document))
    (frame,) = read_dataset(path)
    np.testing.assert_allclose(frame.boxes_cxcywh, [[20, 30, 5, 9]])
    np.testing.assert_allclose(frame.crowd_cxcywh, [[70, 60, 4, 6]])
    write_dataset([frame], tmp_path / "again.json")
    (again,) = read_dataset(tmp_path / "again.json")
    np.testing.assert_allclose(again.crowd_cxcywh, frame.crowd_cxcywh)


def test_missing_silhouette_boxes_are_stood_in_for_by_the_rotated_box_hull(tmp_path: Path) -> None:
    document = {
        "images": [{"id": 1, "file_name": "a.jpg", "width": 101, "height": 101}],
        "annotations": [
            {"id": 1, "image_id": 1, "rotated_box": [80, 50, 10, 20]},
            {"id": 2, "image_id": 1, "rotated_box": [50, 20, 10, 20], "bbox": [44, 9, 11, 22], "area": 150},
        ],
    }
    path = tmp_path / "partial.json"
    path.write_text(json.dumps(document))
    (frame,) = read_dataset(path)
    assert frame.bboxes_xywh is not None and frame.areas_px is not None
    np.testing.assert_array_equal(frame.bboxes_xywh, [[np.nan] * 4, [44, 9, 11, 22]])
    np.testing.assert_array_equal(frame.areas_px, [np.nan, 150])
    write_dataset([frame], tmp_path / "again.json")
    records = json.loads((tmp_path / "again.json").read_text())["annotations"]
    # Right of the principal point (50, 50) the radial axis is +u: the hull is 20 wide, 10 high.
    assert records[0]["bbox"] == [70.0, 45.0, 20.0, 10.0] and records[0]["area"] == 200.0
    assert records[1]["bbox"] == [44.0, 9.0, 11.0, 22.0] and records[1]["area"] == 150.0


def test_a_non_numeric_area_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "bad_area.json"
    path.write_text(json.dumps({
        "images": [{"id": 1, "file_name": "a.jpg", "width": 8, "height": 8}],
        "annotations": [{"id": 1, "image_id": 1, "rotated_box": [1, 2, 3, 4], "area": "big"}],
    }))
    with pytest.raises(DatasetFormatError, match="area must be a number"):
        read_dataset(path)


def test_loaf_release_rotated_boxes_with_an_angle_become_radius_aligned(tmp_path: Path) -> None:
    """The LOAF release writes `rotated_box` as [cx, cy, w, h, angle_deg], the angle turning the box
    counter-clockwise on screen; about the frame centre (511.5, 511.5) of a 1024 px frame:"""
    document = {
        "images": [{"id": 7, "file_name": "loaf.jpg", "width": 1024, "height": 1024}],
        "annotations": [
            # Up-right of the centre, −45 is radial: kept as it is.
            {"id": 1, "image_id": 7, "category_id": 1, "rotated_box": [711.5, 311.5, 30, 90, -45],
             "bbox": [650.0, 250.0, 120.0, 120.0], "area": 2700, "iscrowd": 0},
            # Left of it, −90 is radial.
            {"id": 2, "image_id": 7, "category_id": 1, "rotated_box": [211.5, 511.5, 40, 100, -90],
             "iscrowd": 0},
            # Below it, −90 lies across the ray: w is the radial side.
            {"id": 3, "image_id": 7, "category_id": 1, "rotated_box": [511.5, 811.5, 40, 100, -90],
             "iscrowd": 1},
            # The plain radius-aligned form in the same file.
            {"id": 4, "image_id": 7, "category_id": 1, "rotated_box": [511.5, 211.5, 35, 95],
             "iscrowd": 0},
        ],
    }
    path = tmp_path / "loaf.json"
    path.write_text(json.dumps(document))
    (frame,) = read_dataset(path)
    np.testing.assert_allclose(frame.boxes_cxcywh, [[711.5, 311.5, 30, 90], [211.5, 511.5, 40, 100],
                                                    [511.5, 211.5, 35, 95]], atol=1e-9)
    np.testing.assert_allclose(frame.crowd_cxcywh, [[511.5, 811.5, 100, 40]], atol=1e-9)
    assert frame.bboxes_xywh is not None
    np.testing.assert_array_equal(frame.bboxes_xywh[0], [650.0, 250.0, 120.0, 120.0])
    # Written back in the radius-aligned form, it reads the same.
    write_dataset([frame], tmp_path / "again.json")
    (again,) = read_dataset(tmp_path / "again.json")
    np.testing.assert_allclose(again.boxes_cxcywh, frame.boxes_cxcywh, atol=1e-12)
    np.testing.assert_allclose(again.crowd_cxcywh, frame.crowd_cxcywh, atol=1e-12)


def test_rotated_box_of_another_length_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "bad_box.json"
    path.write_text(json.dumps({
        "images": [{"id": 1, "file_name": "a.jpg", "width": 8, "height": 8}],
        "annotations": [{"id": 1, "image_id": 1, "rotated_box": [1, 2, 3]}],
    }))
    with pytest.raises(DatasetFormatError, match="rotated_box must hold 4 numbers"):
        read_dataset(path)


def _cepdof_file(tmp_path: Path, frame: np.ndarray, boxes: list[list[float]]) -> Path:
    import cv2

    height, width = frame.shape[:2]
    cv2.imwrite(str(tmp_path / "wide.png"), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    path = tmp_path / "wide.json"
    path.write_text(json.dumps({
        "images": [{"id": "w", "file_name": "wide.png", "width": width, "height": height}],
        "annotations": [{"image_id": "w", "bbox": box} for box in boxes],
    }))
    return path


def test_a_wide_circle_gets_the_camera_of_its_fitted_image_circle(tmp_path: Path) -> None:
    """With assumed_lens="image-circle" a frame whose circle is wider than its shorter side gets that
    circle's camera (principal point and focal from the circle), not the shorter side's."""
    from tests.fisheye.circle_frames import CircleFrame, draw_circle_frame

    spec = CircleFrame((656, 540), (330.0, 268.0), 322.0)
    path = _cepdof_file(tmp_path, draw_circle_frame(spec), [[600.0, 270.0, 20.0, 50.0, 0.0]])
    (short,) = read_dataset(path)
    assert short.camera == assumed_camera(656, 540)
    (fitted,) = read_dataset(path, assumed_lens="image-circle")
    camera = fitted.camera
    assert camera is not None and fitted.camera_assumed and camera.id == "assumed"
    np.testing.assert_allclose(camera.principal_point, spec.center_px, atol=1.0)
    assert camera.image_circle_radius_px() == pytest.approx(spec.radius_px, abs=1.0)
    assert fitted.principal_point == camera.principal_point  # the boxes turn about the fitted centre
    # The person near the rim lies beyond the shorter side's circle, inside the fitted one.
    theta, _ = camera.pixels_to_angles(fitted.boxes_cxcywh[:, :2])
    assert np.isfinite(theta).all()
    assert np.isnan(short.camera.pixels_to_angles(short.boxes_cxcywh[:, :2])[0]).all()  # type: ignore[union-attr]


def test_a_frame_without_a_circle_falls_back_to_the_shorter_side_and_says_so(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = _cepdof_file(tmp_path, np.zeros((480, 640, 3), np.uint8), [])
    with caplog.at_level("WARNING", logger="detector.data.readers"):
        (frame,) = read_dataset(path, assumed_lens="image-circle")
    assert frame.camera == assumed_camera(640, 480)
    assert "no image circle" in caplog.text and "shorter side" in caplog.text


def test_an_unknown_assumed_lens_is_refused(tmp_path: Path) -> None:
    path = _cepdof_file(tmp_path, np.zeros((64, 64, 3), np.uint8), [])
    with pytest.raises(ValueError, match="assumed_lens"):
        read_dataset(path, assumed_lens="guess")  # type: ignore[arg-type]
