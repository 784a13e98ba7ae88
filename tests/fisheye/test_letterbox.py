import cv2
import numpy as np
import pytest

from fisheye.letterbox import Letterbox


@pytest.mark.parametrize(
    ("frame_wh", "size", "resized_wh", "offset_xy"),
    [
        ((2048, 2048), 512, (512, 512), (0, 0)),
        ((1920, 1080), 640, (640, 360), (0, 140)),
        ((1080, 1920), 640, (360, 640), (140, 0)),
        ((300, 200), 640, (640, 427), (0, 106)),
        ((1, 1000), 64, (1, 64), (31, 0)),
    ],
)
def test_fit_table(frame_wh: tuple[int, int], size: int, resized_wh: tuple[int, int],
                   offset_xy: tuple[int, int]) -> None:
    box = Letterbox.fit(frame_wh, size)
    assert (box.resized_wh, box.offset_xy, box.size, box.frame_wh) == (resized_wh, offset_xy, size, frame_wh)


@pytest.mark.parametrize("frame_wh", [(0, 100), (100, -1)])
def test_fit_refuses_empty_frames(frame_wh: tuple[int, int]) -> None:
    with pytest.raises(ValueError, match="positive"):
        Letterbox.fit(frame_wh, 512)


@pytest.mark.parametrize(
    "uv",
    [np.zeros((0, 2)), np.array([[0.0, 0.0]]), np.array([[1919.0, 1079.0], [959.5, 539.5], [-0.5, -0.5]])],
)
def test_point_round_trip(uv: np.ndarray) -> None:
    box = Letterbox.fit((1920, 1080), 640)
    inside = box.frame_to_input(uv)
    assert inside.shape == uv.shape
    np.testing.assert_allclose(box.input_to_frame(inside), uv, atol=1e-9)


def test_pixel_centres_follow_resize() -> None:
    box = Letterbox.fit((1920, 1080), 640)
    # The frame's outer edge (−0.5 and W−0.5) lands on the resized region's outer edge.
    edges = box.frame_to_input([[-0.5, -0.5], [1919.5, 1079.5]])
    np.testing.assert_allclose(edges, [[-0.5, 139.5], [639.5, 499.5]], atol=1e-9)


@pytest.mark.parametrize(
    "boxes", [np.zeros((0, 4)), np.array([[960.0, 540.0, 30.0, 90.0], [10.0, 20.0, 1.0, 2.0]])]
)
def test_box_round_trip(boxes: np.ndarray) -> None:
    box = Letterbox.fit((2952, 2952), 512)
    inside = box.boxes_frame_to_input(boxes)
    if len(boxes):
        np.testing.assert_allclose(inside[:, 2:], boxes[:, 2:] * 512 / 2952)
    np.testing.assert_allclose(box.boxes_input_to_frame(inside), boxes, atol=1e-9)


def test_apply_places_the_frame_in_the_middle() -> None:
    frame = np.full((1080, 1920, 3), 200, dtype=np.uint8)
    frame[:, :960] = 50  # left half dark
    box = Letterbox.fit((1920, 1080), 640)
    out = box.apply(frame, pad_value=7)
    assert out.shape == (640, 640, 3) and out.dtype == np.uint8
    assert (out[:140] == 7).all() and (out[500:] == 7).all()
    assert (out[140:500, :310] == 50).all() and (out[140:500, 330:] == 200).all()
    np.testing.assert_array_equal(out[140:500], cv2.resize(frame, (640, 360), interpolation=cv2.INTER_AREA))


def test_apply_refuses_a_frame_of_another_size() -> None:
    with pytest.raises(ValueError, match="letterbox expects"):
        Letterbox.fit((1920, 1080), 640).apply(np.zeros((100, 100, 3), dtype=np.uint8))


def test_scale_xy() -> None:
    assert Letterbox.fit((2048, 1024), 512).scale_xy == (0.25, 0.25)
