from pathlib import Path

import numpy as np
import pytest

from fisheye import CalibrationError, camera_from_dict
from fisheye.ruler_marks import (
    RulerMarks,
    marks_to_csv,
    parse_marks_csv,
    read_marks_csv,
    simulate_ruler_marks,
)

CAMERA = camera_from_dict({
    "id": "lobby-1", "altitude_m": 3.2, "image_size": [2952, 2952], "principal_point": [1480.3, 1469.8],
    "focal_px": [940.0, 940.0], "kb": [1.0, -0.02, 0.001],
})


@pytest.mark.parametrize(
    ("text", "uv", "distance", "rulers", "with_xy"),
    [
        ("u,v,distance_m\n1476,1476,0\n1700,1476,1.5\n", [[1476, 1476], [1700, 1476]], [0, 1.5], ["", ""],
         [False, False]),
        ("# a comment\nruler, u, v, distance_m\n\neast, 1476, 1476, 0\n  # another\neast, 1700.5, 1476, 1\n",
         [[1476, 1476], [1700.5, 1476]], [0, 1], ["east", "east"], [False, False]),
        ("u,v,x_m,y_m\n1476,1476,0,0\n1476,1200,0,2\n", [[1476, 1476], [1476, 1200]], [0, 2], ["", ""],
         [True, True]),
        ("ruler,u,v,distance_m,x_m,y_m\na,1,2,0,,\nb,3,4,5,3,4\n", [[1, 2], [3, 4]], [0, 5], ["a", "b"],
         [False, True]),
    ],
)
def test_parse_marks_table(text: str, uv: list[list[float]], distance: list[float], rulers: list[str],
                           with_xy: list[bool]) -> None:
    marks = parse_marks_csv(text)
    np.testing.assert_array_equal(marks.uv_px, uv)
    np.testing.assert_array_equal(marks.distance_m, distance)
    assert list(marks.ruler) == rulers
    assert marks.has_xy.tolist() == with_xy
    assert marks.is_nadir.tolist() == [d == 0 for d in distance]
    assert len(marks) == len(uv)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty"),
        ("u,v,distance_m\n", "no marks"),
        ("u,v,distance_m,colour\n1,2,3,red\n", "unknown column"),
        ("v,distance_m\n1,2\n", "'u' is missing"),
        ("u,v\n1,2\n", "distance_m column"),
        ("u,v,distance_m\n1,2,abc\n", "line 2: distance_m must be a number"),
        ("u,v,distance_m\n1,2,0\n1,2,-1\n", "line 3: distance_m must be ≥ 0"),
        ("u,v,distance_m\n1,2,0\n1,,1\n", "line 3: u and v are required"),
        ("u,v,distance_m\n1,2,nan\n", "line 2: distance_m must be finite"),
        ("u,v,distance_m,x_m,y_m\n1,2,,,\n", "line 2: give distance_m or both"),
        ("u,v,distance_m,x_m,y_m\n1,2,1,1,\n", "both x_m and y_m"),
        ("u,v,distance_m,x_m,y_m\n1,2,2,1,0\n", "disagrees with distance_m"),
        ("u,v,distance_m\n1,2,3,4\n", "line 2: more fields"),
    ],
)
def test_bad_marks_say_where(text: str, message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        parse_marks_csv(text)


@pytest.mark.parametrize("with_xy", [False, True])
def test_csv_round_trip(tmp_path: Path, with_xy: bool) -> None:
    marks = simulate_ruler_marks(CAMERA, [0, 120, 240], [0.5, 1.0, 7.25], noise_px=0.7, seed=3,
                                 with_xy=with_xy)
    path = tmp_path / "marks.csv"
    path.write_text(marks_to_csv(marks), encoding="utf-8")
    loaded = read_marks_csv(path)
    np.testing.assert_array_equal(loaded.uv_px, marks.uv_px)
    np.testing.assert_array_equal(loaded.distance_m, marks.distance_m)
    np.testing.assert_array_equal(loaded.xy_m, marks.xy_m)
    assert loaded.ruler == marks.ruler


def test_read_missing_marks_file(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match="cannot read marks file"):
        read_marks_csv(tmp_path / "absent.csv")


def test_simulated_marks_lie_on_the_camera() -> None:
    marks = simulate_ruler_marks(CAMERA, [0, 90], [1.0, 2.0, 3.0], with_xy=True)
    assert len(marks) == 7 and marks.ruler[0] == "nadir" and marks.is_nadir.sum() == 1
    np.testing.assert_allclose(CAMERA.pixels_to_floor(marks.uv_px), marks.xy_m, atol=1e-9)
    assert simulate_ruler_marks(CAMERA, [0], [1.0]).has_xy.tolist() == [False, False]


def test_from_arrays_and_checks() -> None:
    marks = RulerMarks.from_arrays([[1, 2], [3, 4]], xy_m=[[0, 0], [3, 4]])
    np.testing.assert_array_equal(marks.distance_m, [0, 5])
    with pytest.raises(CalibrationError, match="distance_m or xy_m"):
        RulerMarks.from_arrays([[1, 2]])
    with pytest.raises(CalibrationError, match="disagree in length"):
        RulerMarks.from_arrays([[1, 2], [3, 4]], [0.0])
    with pytest.raises(CalibrationError, match="u, v must be finite"):
        RulerMarks.from_arrays([[np.nan, 2]], [1.0])
    with pytest.raises(CalibrationError, match="distance_m must be a finite number"):
        RulerMarks.from_arrays([[1, 2]], [np.inf])
