import math

import cv2
import numpy as np
import pytest

from fisheye.boxes import cxcywh_to_corners
from fisheye.rotated import polygon_iou, quad_intersection_areas, rotated_iou, rotated_nms

PP = np.array([512.0, 512.0])
SQUARE = np.array([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]])


def _opencv_iou(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of two radius-aligned boxes with OpenCV's rotated rectangles (width along the ray)."""
    def rect(box: np.ndarray) -> tuple[tuple[float, float], tuple[float, float], float]:
        angle = math.degrees(math.atan2(box[1] - PP[1], box[0] - PP[0]))
        return (float(box[0]), float(box[1])), (float(box[3]), float(box[2])), angle

    status, region = cv2.rotatedRectangleIntersection(rect(a), rect(b))
    inter = 0.0 if status == cv2.INTERSECT_NONE or region is None else cv2.contourArea(region)
    return inter / (a[2] * a[3] + b[2] * b[3] - inter)


def _random_pairs(count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    a = np.column_stack([rng.uniform(300, 700, (count, 2)), rng.uniform(5, 80, (count, 2))])
    b = a.copy()
    b[:, :2] += rng.normal(0, 12, (count, 2))
    b[:, 2:] *= rng.uniform(0.5, 1.5, (count, 2))
    b[: count // 10] = a[: count // 10]  # identical boxes
    b[count // 10: count // 5, :2] = a[count // 10: count // 5, :2]  # same centre, other sides
    return a, b


def _scalar_iou(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of two convex quadrilaterals by plain one-edge-at-a-time clipping (a reference)."""
    def signed_area(poly: list[np.ndarray]) -> float:
        return 0.5 * sum(p[0] * q[1] - p[1] * q[0] for p, q in zip(poly, poly[1:] + poly[:1], strict=True))

    def area(poly: list[np.ndarray]) -> float:
        return abs(signed_area(poly))

    def ccw(quad: np.ndarray) -> list[np.ndarray]:
        points = list(quad)
        return points if signed_area(points) > 0 else points[::-1]

    clip, poly = ccw(b), ccw(a)
    for k in range(4):
        start, end = clip[k], clip[(k + 1) % 4]
        def side(p: np.ndarray, start: np.ndarray = start, end: np.ndarray = end) -> float:
            return float((end[0] - start[0]) * (p[1] - start[1]) - (end[1] - start[1]) * (p[0] - start[0]))
        out: list[np.ndarray] = []
        for i, p in enumerate(poly):
            q = poly[(i + 1) % len(poly)]
            if side(p) >= 0:
                out.append(p)
            if (side(p) > 0 > side(q)) or (side(p) < 0 < side(q)):
                out.append(p + side(p) / (side(p) - side(q)) * (q - p))
        poly = out
        if not poly:
            return 0.0
    inter = area(poly) if len(poly) >= 3 else 0.0
    return inter / (area(list(a)) + area(list(b)) - inter)


def test_rotated_iou_agrees_with_opencv() -> None:
    a, b = _random_pairs(400, seed=1)
    ours = rotated_iou(a, b, PP).diagonal()
    reference = np.array([_opencv_iou(x, y) for x, y in zip(a, b, strict=True)])
    assert (reference > 0).sum() > 300
    # OpenCV intersects in float32: thin slivers differ by up to ~5e-4, typical pairs by < 1e-5.
    np.testing.assert_allclose(ours, reference, atol=1e-3)
    assert np.quantile(np.abs(ours - reference), 0.9) < 1e-5


def test_rotated_iou_agrees_with_plain_clipping() -> None:
    a, b = _random_pairs(200, seed=7)
    ours = rotated_iou(a, b, PP).diagonal()
    corners_a, corners_b = cxcywh_to_corners(a, PP), cxcywh_to_corners(b, PP)
    reference = [_scalar_iou(x, y) for x, y in zip(corners_a, corners_b, strict=True)]
    np.testing.assert_allclose(ours, reference, atol=1e-9)


def test_rotated_iou_matrix_is_pairwise() -> None:
    a, b = _random_pairs(30, seed=2)
    matrix = rotated_iou(a, b, PP)
    assert matrix.shape == (30, 30)
    for i in range(0, 30, 7):
        for j in range(0, 30, 5):
            assert matrix[i, j] == pytest.approx(_opencv_iou(a[i], b[j]), abs=1e-4)
    np.testing.assert_allclose(rotated_iou(a, a, PP).diagonal(), 1.0, atol=1e-12)
    np.testing.assert_allclose(matrix, rotated_iou(b, a, PP).T, atol=1e-12)


@pytest.mark.parametrize(
    ("a", "b", "shape"),
    [
        (np.zeros((0, 4)), np.zeros((0, 4)), (0, 0)),
        (np.zeros((0, 4)), np.array([[1.0, 2.0, 3.0, 4.0]]), (0, 1)),
        (np.array([[1.0, 2.0, 3.0, 4.0]]), np.zeros((0, 4)), (1, 0)),
    ],
)
def test_empty_iou(a: np.ndarray, b: np.ndarray, shape: tuple[int, int]) -> None:
    assert rotated_iou(a, b, PP).shape == shape


@pytest.mark.parametrize(
    ("offset", "expected"),
    [
        ((0.0, 0.0), 1.0),
        ((0.5, 0.0), 1 / 3),
        ((0.5, 0.5), 0.25 / 1.75),
        ((1.0, 0.0), 0.0),  # sharing an edge
        ((1.0, 1.0), 0.0),  # sharing a corner
        ((3.0, 0.0), 0.0),
    ],
)
def test_polygon_iou_hand_cases(offset: tuple[float, float], expected: float) -> None:
    assert polygon_iou(SQUARE, SQUARE + np.array(offset))[0, 0] == pytest.approx(expected, abs=1e-12)


def test_polygon_iou_diamond_in_square_and_containment() -> None:
    square = SQUARE * 2
    diamond = np.array([[[1.0, -1.0], [3.0, 1.0], [1.0, 3.0], [-1.0, 1.0]]])  # area 8, holds the square
    assert polygon_iou(square, diamond)[0, 0] == pytest.approx(4 / 8)
    inner = SQUARE * 0.5 + 0.25
    assert polygon_iou(SQUARE, inner)[0, 0] == pytest.approx(0.25)
    # Clockwise vertex order gives the same result.
    assert polygon_iou(SQUARE[:, ::-1], inner)[0, 0] == pytest.approx(0.25)


def test_quad_intersection_areas_of_nothing() -> None:
    assert quad_intersection_areas(np.zeros((0, 4, 2)), np.zeros((0, 4, 2))).shape == (0,)


def test_nan_boxes_have_zero_iou() -> None:
    boxes = np.array([[np.nan, 500.0, 10.0, 20.0], [600.0, 500.0, 10.0, 20.0]])
    iou = rotated_iou(boxes, boxes, PP)
    assert iou[0, 0] == 0.0 and iou[1, 1] == pytest.approx(1.0)


# A box centred exactly on the principal point has angle atan2(0, 0) = 0: its h axis lies along +u.
AT_PP = np.array([512.0, 512.0, 20.0, 40.0])


@pytest.mark.parametrize(
    ("other", "expected"),
    [
        (AT_PP, 1.0),
        (np.array([512.0, 512.0, 40.0, 20.0]), 400 / 1200),  # the same box turned 90°: a cross
        (np.array([522.0, 512.0, 20.0, 40.0]), 600 / 1000),  # 10 px right: h along +u too
        (np.array([512.0, 522.0, 20.0, 40.0]), 400 / 1200),  # 10 px down: h along +v
        (np.array([512.0, 502.0, 20.0, 40.0]), 400 / 1200),  # 10 px up: h along −v
        (np.array([542.0, 512.0, 20.0, 40.0]), 200 / 1400),  # touching only by 10 px of h
    ],
)
def test_rotated_iou_of_boxes_on_the_principal_point(other: np.ndarray, expected: float) -> None:
    iou = rotated_iou(AT_PP[None], other[None], PP)[0, 0]
    assert iou == pytest.approx(expected, abs=1e-12)
    assert rotated_iou(other[None], AT_PP[None], PP)[0, 0] == pytest.approx(iou, abs=1e-12)


def test_rotated_nms_of_boxes_on_the_principal_point() -> None:
    boxes = np.array([
        AT_PP,                          # best
        AT_PP,                          # its twin
        [512.0, 512.0, 40.0, 20.0],     # same centre, turned: IoU 1/3 with the best
        [522.0, 512.0, 20.0, 40.0],     # 10 px right: IoU 0.6 with the best, 1/3 with the turned one
    ])
    scores = np.array([0.9, 0.8, 0.7, 0.6])
    assert rotated_nms(boxes, scores, PP, iou_threshold=0.5).tolist() == [0, 2]
    assert rotated_nms(boxes, scores, PP, iou_threshold=0.7).tolist() == [0, 2, 3]
    # Scores reversed: the right-hand box now leads and suppresses both boxes on the principal point.
    assert rotated_nms(boxes, scores[::-1], PP, iou_threshold=0.5).tolist() == [3, 2]


def test_rotated_nms_hand_made() -> None:
    # A and B overlap (IoU 2/3), C overlaps neither; D is B's twin with the lowest score.
    boxes = np.array([
        [700.0, 512.0, 20.0, 60.0],   # A
        [710.0, 512.0, 20.0, 60.0],   # B: 10 px further out along the ray
        [512.0, 300.0, 20.0, 60.0],   # C
        [710.0, 512.0, 20.0, 60.0],   # D
    ])
    scores = np.array([0.8, 0.9, 0.7, 0.1])
    assert rotated_iou(boxes[:1], boxes[1:2], PP)[0, 0] == pytest.approx(50 / 70)
    assert rotated_nms(boxes, scores, PP, iou_threshold=0.5).tolist() == [1, 2]
    assert rotated_nms(boxes, scores, PP, iou_threshold=0.8).tolist() == [1, 0, 2]
    assert rotated_nms(boxes, scores, PP, iou_threshold=1.0).tolist() == [1, 0, 2, 3]


def test_rotated_nms_edge_cases() -> None:
    assert rotated_nms(np.zeros((0, 4)), np.zeros(0), PP, 0.5).tolist() == []
    assert rotated_nms([[600.0, 500.0, 10.0, 20.0]], [0.3], PP, 0.5).tolist() == [0]
    with pytest.raises(ValueError, match="scores"):
        rotated_nms(np.zeros((2, 4)), np.zeros(3), PP, 0.5)


def test_corner_helper_matches_opencv_box_points() -> None:
    box = np.array([700.0, 600.0, 20.0, 60.0])
    angle = math.degrees(math.atan2(600.0 - PP[1], 700.0 - PP[0]))
    expected = cv2.boxPoints(((700.0, 600.0), (60.0, 20.0), angle)).astype(np.float64)
    corners = cxcywh_to_corners(box[None], PP)[0]
    distances = np.linalg.norm(corners[:, None] - expected[None], axis=2)
    assert distances.min(axis=1).max() < 1e-3
