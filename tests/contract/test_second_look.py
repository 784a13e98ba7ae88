"""The second look: which detections get a patch, the patch's geometry, what a patch may add, how
a view names and reports it, and the pipeline running it (with the polar test double)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from polar_double import BOX_WH, METADATA, save_polar_double

from contract import (
    FrameDetections,
    ModelInfo,
    OnnxModel,
    OperatingPoint,
    RawOutputs,
    SessionThreads,
    parse_metadata,
)
from contract import second_look as look
from contract.detect import second_look
from contract.views import DEFAULT_VIEW, PlannedInput, PolarInput, view_plan
from fisheye import camera_from_dict
from fisheye.view_plan import (
    SECOND_LOOK_FULL_PIXELS,
    SECOND_LOOK_MAX_ZOOM,
    SECOND_LOOK_PATCH_PX,
    ViewPlanConfig,
)
from service.pipeline import Pipeline, PipelineConfig

CAMERA = {"id": "cam", "altitude_m": 3.0, "image_size": [1024, 1024], "principal_point": [511.5, 511.5],
          "focal_px": [320.0, 320.0], "kb": [1.0]}
LOOKING = dataclasses.replace(DEFAULT_VIEW, second_look_pixels=SECOND_LOOK_FULL_PIXELS)
ONE_BAND = dataclasses.replace(LOOKING, scales=(1.0,), nadir_fraction=None)


def _info(tmp_path: Path, **kwargs: object) -> ModelInfo:
    path = save_polar_double(tmp_path / "planned.onnx", planned=True, **kwargs)
    return OnnxModel(path, SessionThreads(1)).info


def _box(pp: np.ndarray, radius: float, angle: float, along: float, across: float) -> np.ndarray:
    """A radius-aligned frame box at `radius` px and `angle` of `along` x `across` px."""
    centre = pp + radius * np.array([np.cos(angle), np.sin(angle)])
    return np.array([[centre[0], centre[1], across, along]])


def test_patches_go_to_small_uncertain_detections_at_the_zoom_of_their_band(tmp_path: Path) -> None:
    camera = camera_from_dict(CAMERA)
    plan = view_plan(_info(tmp_path), camera, ONE_BAND)
    band = look.band_grids(plan)[0]
    pp = np.asarray(camera.principal_point)
    # 30 frame px along at radius 300 is 30 * rows/px band rows: well under MAX_ALONG_PX
    small = _box(pp, 300.0, 0.7, 30.0, 14.0)
    long_ = _box(pp, 300.0, 2.0, 1.2 * look.MAX_ALONG_PX / band.px_per_radius_px, 14.0)
    over_centre = _box(pp, 5.0, 0.0, 60.0, 60.0)
    boxes = np.concatenate([small, small, long_, over_centre])
    scores = np.array([0.9, 0.5, 0.4, 0.3])  # the sure one is not looked at again
    patches = look.plan_patches(plan, boxes, scores, (float(pp[0]), float(pp[1])))
    assert [p.detection for p in patches] == [1]
    grid = patches[0].grid
    # 30 frame px are under 4 rows of the double's coarse band: zoomed as far as a patch may be
    zoom = plan.second_look_zoom_for(30.0 * band.px_per_radius_px)
    assert zoom == SECOND_LOOK_MAX_ZOOM
    assert grid.width == round(band.width * zoom)
    assert grid.px_per_radius_px == pytest.approx(band.px_per_radius_px * zoom, rel=1e-6)
    width, height = grid.strip_wh
    assert all(SECOND_LOOK_PATCH_PX[0] <= side <= SECOND_LOOK_PATCH_PX[1] and side % 32 == 0
               for side in (width, height))
    centre = grid.frame_to_strip(small[:, :2])[0]
    np.testing.assert_allclose(centre, [(width - 1) / 2, (height - 1) / 2], atol=1.0)
    assert look.plan_patches(dataclasses.replace(plan, second_look_patches=0), boxes, scores,
                             (float(pp[0]), float(pp[1]))) == []


def test_a_far_persons_patch_is_zoomed_to_the_target_rows(tmp_path: Path) -> None:
    camera = camera_from_dict(CAMERA)
    plan = view_plan(_info(tmp_path), camera, ONE_BAND)
    target = plan.second_look_target_rows
    assert target == ONE_BAND.second_look_target_rows > 0
    # long enough at the zoom of every patch: that zoom; shorter: zoomed to the target, up to 4x
    assert plan.second_look_zoom_for(target / plan.second_look_zoom) == plan.second_look_zoom
    assert plan.second_look_zoom_for(40.0) == plan.second_look_zoom
    assert plan.second_look_zoom_for(target / 3) == pytest.approx(3.0)
    assert plan.second_look_zoom_for(target / 8) == SECOND_LOOK_MAX_ZOOM
    fixed = view_plan(_info(tmp_path), camera, dataclasses.replace(ONE_BAND, second_look_target_rows=0))
    assert fixed.second_look_zoom_for(2.0) == fixed.second_look_zoom
    # in the frame: a person 16 band rows long comes out 48 rows long in its patch
    band = look.band_grids(plan)[0]
    pp = np.asarray(camera.principal_point)
    person = _box(pp, 400.0, 1.0, (target / 3) / band.px_per_radius_px, 40.0)
    patch = look.plan_patches(plan, person, np.array([0.3]), (float(pp[0]), float(pp[1])))[0]
    _, y1, _, y2 = patch.grid.radius_aligned_to_polar(person)[0]
    assert y2 - y1 == pytest.approx(target, rel=0.02)


@pytest.mark.parametrize("rows", [-1.0, SECOND_LOOK_PATCH_PX[1] / 3 + 1])
def test_a_target_that_no_patch_could_hold_is_refused(rows: float) -> None:
    with pytest.raises(ValueError, match="second_look_target_rows"):
        dataclasses.replace(LOOKING, second_look_target_rows=rows)


def test_at_most_the_planned_number_of_patches_best_scores_first(tmp_path: Path) -> None:
    camera = camera_from_dict(CAMERA)
    plan = view_plan(_info(tmp_path), camera, dataclasses.replace(ONE_BAND, second_look_patches=3))
    pp = np.asarray(camera.principal_point)
    boxes = np.concatenate([_box(pp, 350.0, k * 0.5, 30.0, 14.0) for k in range(6)])
    scores = np.linspace(0.6, 0.1, 6)
    patches = look.plan_patches(plan, boxes, scores, (float(pp[0]), float(pp[1])))
    assert [p.detection for p in patches] == [0, 1, 2]


def test_a_patch_adds_whole_central_short_boxes_that_are_no_part_of_a_larger_one(tmp_path: Path) -> None:
    camera = camera_from_dict(CAMERA)
    plan = view_plan(_info(tmp_path), camera, ONE_BAND)
    pp = np.asarray(camera.principal_point)
    band = look.band_grids(plan)[0]
    target = _box(pp, 300.0, 0.7, 30.0, 14.0)
    patch = look.plan_patches(plan, target, np.array([0.5]), (float(pp[0]), float(pp[1])))[0]
    width, height = patch.grid.strip_wh
    # boxes given in the patch's strip, read back to the frame through it
    central = patch.grid.polar_to_radius_aligned(np.array([[width / 2 - 8, height / 2 - 20, width / 2 + 8,
                                                            height / 2 + 20]]))
    at_edge = patch.grid.polar_to_radius_aligned(np.array([[0.0, height / 2 - 20, 16.0, height / 2 + 20]]))
    keeps = look.patch_keeps(patch, np.concatenate([central, at_edge]))
    assert keeps.tolist() == [True, False]
    long_in_band = _box(pp, 300.0, 0.7, 1.6 * look.MAX_ALONG_PX / band.px_per_radius_px, 10.0)
    assert not look.patch_keeps(patch, long_in_band)[0]
    larger = central * np.array([1, 1, 2, 2])  # the same centre, twice the size each way
    elsewhere = _box(pp, 300.0, 2.5, 2 * central[0, 3], 2 * central[0, 2])
    assert look.parts_of(band, central, larger).tolist() == [True]
    assert look.parts_of(band, central, elsewhere).tolist() == [False]
    assert look.parts_of(band, central, np.zeros((0, 4))).tolist() == [False]


def test_the_view_names_and_reports_its_second_look(tmp_path: Path) -> None:
    info = _info(tmp_path)
    camera = camera_from_dict(CAMERA)
    plan = view_plan(info, camera, LOOKING)
    assert plan.layout.endswith("+look") and plan.second_look_patches == LOOKING.second_look_patches
    assert plan.public()["second_look"] == {
        "max_patches": 12, "zoom": 2.0, "target_rows": 48.0, "max_zoom": SECOND_LOOK_MAX_ZOOM,
        "patch_px": list(SECOND_LOOK_PATCH_PX),
        "max_pixels": SECOND_LOOK_FULL_PIXELS,
        "max_cost_ratio": round(SECOND_LOOK_FULL_PIXELS / plan.reference_pixels, 3)}
    assert plan.public()["cost_ratio"] == round(plan.pixels / plan.reference_pixels, 3)  # the same scale
    for off in (DEFAULT_VIEW, dataclasses.replace(LOOKING, second_look_patches=0)):  # by default: none
        without = view_plan(info, camera, off)
        assert without.public()["second_look"] is None and not without.layout.endswith("+look")
    few = view_plan(info, camera, dataclasses.replace(LOOKING, second_look_pixels=5000))
    assert few.second_look_patches == 0 and any("no second look" in note for note in few.notes)


def test_the_second_look_keeps_within_its_pixels(tmp_path: Path) -> None:
    camera = camera_from_dict(CAMERA)
    plan = view_plan(_info(tmp_path), camera, ONE_BAND)
    pp = (float(camera.principal_point[0]), float(camera.principal_point[1]))
    band = look.band_grids(plan)[0]
    along = 30.0 / band.px_per_radius_px  # 30 band rows
    boxes = np.concatenate([_box(np.asarray(pp), 400.0, k * 0.5, along, 40.0) for k in range(12)])
    every = look.plan_patches(plan, boxes, np.full(12, 0.4), pp)
    sizes = [p.grid.strip_wh[0] * p.grid.strip_wh[1] for p in every]
    budget = sum(sizes[:3])
    some = look.plan_patches(dataclasses.replace(plan, second_look_pixels=budget), boxes,
                             np.full(12, 0.4), pp)
    assert len(every) == 12 and 3 <= len(some) < 12  # the patches past it left out, smaller ones after kept
    assert sum(p.grid.strip_wh[0] * p.grid.strip_wh[1] for p in some) <= budget
    # their canvas, gutters included, within it too: the last patches left out until it fits
    fitted, canvas = look.fit(some, budget)
    assert fitted == some[:len(fitted)] and 1 <= len(fitted) < len(some)
    assert canvas.size_wh[0] * canvas.size_wh[1] <= budget
    grown = look.pack([p.grid.strip_wh for p in some[:len(fitted) + 1]])
    assert grown.size_wh[0] * grown.size_wh[1] > budget
    assert look.fit(some[:1], 1)[0] == some[:1]  # one patch is always run


@pytest.mark.parametrize("change", [{"second_look_patches": -1}, {"second_look_patches": 65},
                                    {"second_look_zoom": 1.0}, {"second_look_zoom": 4.5},
                                    {"second_look_pixels": -1}, {"second_look_pixels": 64 * 256 * 256 + 1}])
def test_a_bad_second_look_is_refused(change: dict[str, float]) -> None:
    with pytest.raises(ValueError, match="second_look"):
        ViewPlanConfig(**change)  # type: ignore[arg-type]


def test_a_view_with_the_second_look_takes_its_own_point_or_that_of_the_view_without_it() -> None:
    props = {**METADATA, "fishloc.view_planned": "1",
             "fishloc.view_operating_points": '{"1band+nadir": {"min_score": 0.24, "nms_iou": 0.35}}'}
    older = parse_metadata(props, "older.onnx")
    assert older.point_for("1band+nadir+look") == OperatingPoint(0.24, 0.35)
    assert older.point_for("2band+look") == OperatingPoint(older.default_min_score, older.nms_iou)
    own = '{"1band+nadir": {"min_score": 0.24, "nms_iou": 0.35}, "1band+nadir+look": {"min_score": 0.3, ' \
          '"nms_iou": 0.3}}'
    newer = parse_metadata({**props, "fishloc.view_operating_points": own}, "newer.onnx")
    assert newer.point_for("1band+nadir+look") == OperatingPoint(0.3, 0.3)


def _disc_frame(camera: object, xy_m: tuple[float, float]) -> tuple[bytes, np.ndarray]:
    import cv2

    uv = camera.floor_to_pixels(np.array([xy_m]))[0]  # type: ignore[attr-defined]
    frame = np.full((1024, 1024, 3), 30, dtype=np.uint8)
    cv2.circle(frame, (round(uv[0]), round(uv[1])), 6, (255, 255, 255), -1)
    ok, data = cv2.imencode(".png", frame)
    assert ok
    return data.tobytes(), uv


def test_the_pipeline_adds_what_the_patch_finds_at_its_zoom(tmp_path: Path) -> None:
    # The double boxes the bright disc with BOX_WH input px whatever the input: in the patch, at
    # `zoom` times the band's rows and columns a frame px, that box is 1 / zoom of the first look's
    # in the frame, on the same centre: 2 for every patch, 48 / 20 = 2.4 where a person under 24
    # band rows is zoomed to 48 (`second_look_target_rows`). Its score (0.5) is under BELOW_SCORE, so
    # the first look's box gets a patch.
    path = save_polar_double(tmp_path / "planned.onnx", planned=True, score=0.5)
    model = OnnxModel(path, SessionThreads(1))
    camera = camera_from_dict(CAMERA)
    data, uv = _disc_frame(camera, (2.0, 1.5))
    plain = Pipeline(model, PipelineConfig(view=dataclasses.replace(ONE_BAND, second_look_pixels=0))).detect(
        data, camera, min_score=0.3).detections
    assert len(plain.scores) == 1
    first = plain.cxcywh[0]
    for view, zoom in ((dataclasses.replace(ONE_BAND, second_look_target_rows=0), 2.0), (ONE_BAND, 2.4)):
        assert view_plan(model.info, camera, view).second_look_zoom_for(BOX_WH[1]) == pytest.approx(zoom)
        looking = Pipeline(model, PipelineConfig(view=view)).detect(data, camera, min_score=0.3).detections
        assert len(looking.scores) == 2
        np.testing.assert_allclose(looking.cxcywh[0], first, atol=1e-3)  # the first look's box stays
        second = looking.cxcywh[1]
        # on the disc, as the first look's box is (the patch's columns are finer: it may be nearer)
        assert np.hypot(*(second[:2] - uv)) <= max(np.hypot(*(first[:2] - uv)), 1.5)
        np.testing.assert_allclose(second[2:], first[2:] / zoom, rtol=0.05)
    assert BOX_WH[1] / 2 < look.MAX_ALONG_PX
    # a threshold over the double's score leaves nothing, looked at or not
    above_all = Pipeline(model, PipelineConfig(view=ONE_BAND)).detect(data, camera, min_score=0.6)
    assert len(above_all.detections) == 0


def test_the_nadir_discs_people_keep_the_threshold_of_the_view_without_the_look(tmp_path: Path) -> None:
    # The view's own point keeps people from 0.24, the look's from 0.3 (for its patches' people).
    # A person scoring 0.27 below the lens, where no patch looks, is still reported with the look;
    # one at the same score in the band is looked at again, scores 0.27 in its patch too, and is not.
    points = '{"1band+nadir": {"min_score": 0.24, "nms_iou": 0.35}, ' \
             '"1band+nadir+look": {"min_score": 0.3, "nms_iou": 0.35}}'
    path = save_polar_double(tmp_path / "planned.onnx", planned=True, score=0.27,
                             metadata={**METADATA, "fishloc.view_operating_points": points})
    model = OnnxModel(path, SessionThreads(1))
    camera = camera_from_dict(CAMERA)
    view = dataclasses.replace(LOOKING, scales=(1.0,))
    plan = view_plan(model.info, camera, view)
    assert plan.layout == "1band+nadir+look" and plan.nadir is not None
    looking = Pipeline(model, PipelineConfig(view=view))
    plain = Pipeline(model, PipelineConfig(view=dataclasses.replace(view, second_look_pixels=0)))
    below, uv = _disc_frame(camera, (0.0, 0.0))
    away, _ = _disc_frame(camera, (2.0, 1.5))
    found = looking.detect(below, camera).detections
    assert len(found.scores) >= 1
    nearest = int(np.argmin(np.hypot(*(found.cxcywh[:, :2] - uv).T)))
    assert np.hypot(*(found.cxcywh[nearest, :2] - uv)) < plan.nadir.owned_px
    assert found.scores[nearest] >= 0.3  # 0.27 on the view's scale: 0.24 -> 0.3
    assert len(plain.detect(below, camera).detections.scores) >= 1
    assert len(looking.detect(away, camera).detections.scores) == 0
    assert len(plain.detect(away, camera).detections.scores) == 1


def test_nadir_scores_map_the_view_threshold_to_the_looks_in_the_disc_alone(tmp_path: Path) -> None:
    camera = camera_from_dict(CAMERA)
    plan = view_plan(_info(tmp_path), camera, dataclasses.replace(LOOKING, scales=(1.0,)))
    assert plan.nadir is not None
    pp = (float(camera.principal_point[0]), float(camera.principal_point[1]))
    inside = np.repeat(_box(np.asarray(pp), 0.5 * plan.nadir.owned_px, 1.0, 40.0, 40.0), 5, axis=0)
    outside = _box(np.asarray(pp), 2.0 * plan.nadir.owned_px, 1.0, 40.0, 40.0)
    scores = np.array([0.0, 0.12, 0.24, 0.27, 1.0, 0.27])
    mapped = look.nadir_scores(plan, np.concatenate([inside, outside]), scores, pp, 0.3, 0.24)
    np.testing.assert_allclose(mapped[:5], [0.0, 0.15, 0.3, 0.3 + 0.03 * 0.7 / 0.76, 1.0])
    assert mapped[5] == 0.27  # outside the disc: as the network scored it
    assert np.all(np.diff(mapped[:5]) > 0)  # the disc's order stays
    np.testing.assert_array_equal(look.nadir_scores(plan, np.concatenate([inside, outside]), scores, pp,
                                                    0.3, 0.3), scores)
    for edge in ((1.0, 0.24), (0.3, 0.0)):  # a point at 0 or 1: nothing to map between
        np.testing.assert_array_equal(look.nadir_scores(plan, np.concatenate([inside, outside]), scores, pp,
                                                        *edge), scores)
    no_nadir = view_plan(_info(tmp_path), camera, ONE_BAND)
    assert no_nadir.nadir is None
    np.testing.assert_array_equal(look.nadir_scores(no_nadir, np.concatenate([inside, outside]), scores, pp,
                                                    0.3, 0.24), scores)


class _PatchModel:
    """A model that answers every patch with one box, given in that patch's px, and its foot 30 px
    below the box's bottom: a stand-in for the network, to check what the second look keeps."""

    def __init__(self, info: ModelInfo, box_xyxy: np.ndarray, score: float) -> None:
        self.info, self.box, self.score = info, box_xyxy, score

    def run(self, image: np.ndarray) -> RawOutputs:
        foot = np.array([[(self.box[0] + self.box[2]) / 2, self.box[3] + 30.0]], dtype=np.float32)
        return RawOutputs(self.box[None].astype(np.float32), np.array([self.score], dtype=np.float32), foot)

    def run_boxes(self, image: np.ndarray) -> RawOutputs:
        return self.run(image)


@pytest.mark.parametrize("same_person_iou", [look.SAME_PERSON_IOU, 1.1])
def test_a_person_both_looks_found_stands_at_the_first_looks_foot(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, same_person_iou: float) -> None:
    monkeypatch.setattr(look, "SAME_PERSON_IOU", same_person_iou)
    info = _info(tmp_path)
    camera = camera_from_dict(CAMERA)
    plan = view_plan(info, camera, ONE_BAND)
    pp = (float(camera.principal_point[0]), float(camera.principal_point[1]))
    first_box = _box(np.asarray(pp), 300.0, 0.7, 30.0, 14.0)
    first = FrameDetections(first_box, np.array([0.5]), pp, foot_px=np.array([[700.0, 800.0]]))
    patch = look.plan_patches(plan, first_box, first.scores, pp)[0]
    # the patch sees the same person, a little more sure of them
    model = _PatchModel(info, patch.grid.radius_aligned_to_polar(first_box)[0], 0.6)
    image = np.zeros((1024, 1024, 3), dtype=np.uint8)
    found = second_look(model, image, (1.0, 1.0), PlannedInput(plan), first, 0.35)
    assert found.scores.tolist() == pytest.approx([0.6])  # the patch's box won the NMS
    np.testing.assert_allclose(found.boxes_cxcywh[0], first_box[0], atol=0.5)
    if same_person_iou <= 1.0:
        np.testing.assert_allclose(found.foot_px[0], [700.0, 800.0])
    else:  # no one is the same person: the patch's own foot, 30 patch rows below its box
        assert np.hypot(*(found.foot_px[0] - [700.0, 800.0])) > 50


@pytest.mark.parametrize("seed", range(6))
def test_patches_pack_apart_on_the_stride_in_no_more_px_than_a_row_or_a_column(seed: int) -> None:
    rng = np.random.default_rng(seed)
    low, high = SECOND_LOOK_PATCH_PX
    count = int(rng.integers(1, 13))
    sizes = [(int(w), int(h)) for w, h in rng.integers(low // 32, high // 32 + 1, (count, 2)) * 32]
    canvas = look.pack(sizes)
    width, height = canvas.size_wh
    assert width % 32 == 0 and height % 32 == 0
    rects = [(x, y, x + w, y + h) for (x, y), (w, h) in zip(canvas.offsets, sizes, strict=True)]
    for x1, y1, x2, y2 in rects:
        assert x1 % 32 == 0 and y1 % 32 == 0 and min(x1, y1) >= 0 and x2 <= width and y2 <= height
    for a, (ax1, ay1, ax2, ay2) in enumerate(rects):  # a gutter between every two patches
        for bx1, by1, bx2, by2 in rects[a + 1:]:
            assert (ax2 + look.GUTTER_PX <= bx1 or bx2 + look.GUTTER_PX <= ax1
                    or ay2 + look.GUTTER_PX <= by1 or by2 + look.GUTTER_PX <= ay1)
    gutters = look.GUTTER_PX * (len(sizes) - 1)
    one_row = (sum(w for w, _ in sizes) + gutters) * max(h for _, h in sizes)
    one_column = max(w for w, _ in sizes) * (sum(h for _, h in sizes) + gutters)
    assert width * height <= min(one_row, one_column)


def test_a_canvas_holds_each_patch_at_its_offset_and_gives_each_its_own_people() -> None:
    canvas = look.pack([(96, 128), (160, 96), (96, 96)])
    images = [np.full((h, w, 3), 50 * (i + 1), dtype=np.uint8) for i, (w, h) in enumerate(canvas.sizes_wh)]
    pasted = canvas.paste(images, pad_value=7)
    for (x, y), (w, h), image in zip(canvas.offsets, canvas.sizes_wh, images, strict=True):
        np.testing.assert_array_equal(pasted[y:y + h, x:x + w], image)
    assert (pasted == 7).sum() == pasted.size - 3 * sum(w * h for w, h in canvas.sizes_wh)
    # one person in each patch, given at (10, 20)-(30, 60) of it, and one in a gutter
    local = np.array([10.0, 20.0, 30.0, 60.0], dtype=np.float32)
    boxes = [local + np.tile(np.array(offset, dtype=np.float32), 2) for offset in canvas.offsets]
    (x, y), (w, _) = canvas.offsets[0], canvas.sizes_wh[0]
    boxes.append(np.array([x + w + 4, y, x + w + 28, y + 40], dtype=np.float32))
    raw = RawOutputs(np.stack(boxes), np.array([0.9, 0.8, 0.7, 0.6], dtype=np.float32),
                     np.stack(boxes)[:, 2:].copy())
    pieces = canvas.split(raw)
    assert [len(piece.scores) for piece in pieces] == [1, 1, 1]
    for piece, score in zip(pieces, [0.9, 0.8, 0.7], strict=True):
        np.testing.assert_allclose(piece.boxes[0], local)
        np.testing.assert_allclose(piece.foot[0], local[2:])
        assert piece.scores[0] == pytest.approx(score)


class _BlobModel:
    """A stand-in for the network: a BOX_WH box on every bright blob of its input, score 0.6."""

    def __init__(self, info: ModelInfo) -> None:
        self.info, self.runs = info, 0

    def run(self, image: np.ndarray) -> RawOutputs:
        import cv2

        self.runs += 1
        count, _, _, centroids = cv2.connectedComponentsWithStats((image.sum(axis=2) > 600).astype(np.uint8))
        centres = centroids[1:count].astype(np.float32)
        half = np.array(BOX_WH, dtype=np.float32) / 2
        boxes = np.concatenate([centres - half, centres + half], axis=1).reshape(-1, 4)
        return RawOutputs(boxes, np.full(len(boxes), 0.6, dtype=np.float32), None)

    def run_boxes(self, image: np.ndarray) -> RawOutputs:
        return self.run(image)


def test_the_patches_run_at_once_find_what_each_finds_alone(tmp_path: Path) -> None:
    import cv2

    info = _info(tmp_path)
    camera = camera_from_dict(CAMERA)
    plan = view_plan(info, camera, ONE_BAND)
    pp = (float(camera.principal_point[0]), float(camera.principal_point[1]))
    image = np.full((1024, 1024, 3), 30, dtype=np.uint8)
    spots = [(300.0, 0.7), (320.0, 2.5), (280.0, -1.9)]
    first_boxes = np.concatenate([_box(np.asarray(pp), r, a, 30.0, 14.0) for r, a in spots])
    for cx, cy, *_ in first_boxes:
        cv2.circle(image, (round(cx), round(cy)), 5, (255, 255, 255), -1)
    first = FrameDetections(first_boxes, np.array([0.5, 0.45, 0.4]), pp)
    model = _BlobModel(info)
    found = second_look(model, image, (1.0, 1.0), PlannedInput(plan), first, 0.35)
    assert model.runs == 1  # one canvas
    alone = []
    for patch in look.plan_patches(plan, first_boxes, first.scores, pp):
        raw = model.run(patch.grid.unwrap(image, border_value=info.pad_value))
        alone.append(PolarInput(patch.grid).boxes_to_frame(raw.boxes.astype(np.float64)))
    assert len(alone) == 3 and all(len(boxes) == 1 for boxes in alone)
    added = found.boxes_cxcywh[np.isclose(found.scores, 0.6)]
    assert len(added) == 3
    for boxes in alone:  # each patch's person, read back to the frame where it alone puts them
        assert np.abs(added - boxes[0]).max(axis=1).min() < 1e-3
