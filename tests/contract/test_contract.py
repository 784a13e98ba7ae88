"""The contract reader: metadata of both views, signature checks, and the polar view end to end
through the service's pipeline with a test-double model."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from polar_double import BOX_WH, METADATA, OVERLAP, SCORE, WIDTH, save_polar_double

from contract import (
    ModelError,
    ModelInfo,
    ModelRunner,
    OnnxModel,
    PolarSpec,
    SessionThreads,
    metadata_props,
    parse_metadata,
)
from contract.views import DEFAULT_VIEW, mapping_layout, min_decoded_side, view_reference
from fisheye import FisheyeCamera, camera_from_dict, foot_points
from fisheye.view_plan import nadir_side
from service.frame_decode import FrameError
from service.pipeline import Pipeline, PipelineConfig, ViewBudgetError

CAMERA = {"id": "cam", "altitude_m": 3.0, "image_size": [1024, 1024], "principal_point": [511.5, 511.5],
          "focal_px": [320.0, 320.0], "kb": [1.0]}


def _person_frame(camera: FisheyeCamera, xy_m: tuple[float, float]) -> tuple[bytes, np.ndarray]:
    """A dark frame with a bright disc on the floor point `xy_m`: JPEG bytes and the disc's pixel."""
    import cv2

    uv = camera.floor_to_pixels(np.array([xy_m]))[0]
    frame = np.full((1024, 1024, 3), 30, dtype=np.uint8)
    cv2.circle(frame, (round(uv[0]), round(uv[1])), 14, (255, 255, 255), -1)
    ok, data = cv2.imencode(".png", frame)
    assert ok
    return data.tobytes(), uv


def test_metadata_round_trip_for_both_views() -> None:
    polar = ModelInfo(name="m", version="1", view="polar", input_size=64, pad_value=0, default_min_score=0.4,
                      trained_on="x", box_format="xyxy_polar", licence="Apache-2.0",
                      polar=PolarSpec(width=256, overlap=32, max_theta_deg=88.0))
    fisheye = ModelInfo(name="m", version="1", view="fisheye", input_size=64, pad_value=0,
                        default_min_score=0.4, trained_on="x", box_format="cxcywh_radius_aligned")
    for info in (polar, fisheye):
        assert parse_metadata(metadata_props(info), "test") == info
    assert polar.input_wh == (288, 64) and fisheye.input_wh == (64, 64)


@pytest.mark.parametrize(("change", "message"), [
    ({"fishloc.polar_width": None}, "fishloc.polar_width"),
    ({"fishloc.box_format": "cxcywh_radius_aligned"}, "xyxy_polar"),
    ({"fishloc.view": "sideways"}, "unknown view"),
    ({"fishloc.polar_overlap": "9999"}, "overlap"),
    ({"fishloc.input_size": None}, "fishloc.input_size"),
])
def test_bad_metadata_is_refused(change: dict[str, str | None], message: str) -> None:
    props = {k: v for k, v in {**METADATA, **change}.items() if v is not None}
    with pytest.raises(ModelError, match=message):
        parse_metadata(props, "bad.onnx")


def test_a_foot_output_of_the_wrong_shape_is_refused(tmp_path: Path) -> None:
    path = save_polar_double(tmp_path / "bad_foot.onnx", bad_foot=True)
    with pytest.raises(ModelError, match="'foot' has shape"):
        OnnxModel(path, SessionThreads(1))


def test_an_input_that_does_not_match_the_strip_is_refused(tmp_path: Path) -> None:
    path = save_polar_double(tmp_path / "wide.onnx", metadata={**METADATA, "fishloc.polar_width": "512"})
    with pytest.raises(ModelError, match="'image' has shape"):
        OnnxModel(path, SessionThreads(1))


@pytest.mark.parametrize("with_foot", [False, True])
@pytest.mark.parametrize("xy_m", [(1.5, 0.8), (-2.0, -3.0), (0.4, -4.5)])
def test_polar_pipeline_places_the_person(tmp_path: Path, with_foot: bool, xy_m: tuple[float, float]) -> None:
    model = OnnxModel(save_polar_double(tmp_path / "polar.onnx", foot=with_foot), SessionThreads(1))
    assert model.has_foot == with_foot and model.info.view == "polar"
    pipeline = Pipeline(model, PipelineConfig())
    camera = camera_from_dict(CAMERA)
    data, uv = _person_frame(camera, xy_m)
    result = pipeline.detect(data, camera)
    detections = result.detections
    assert detections.scores.tolist() == pytest.approx([SCORE], abs=1e-3)
    box = detections.cxcywh[0]
    pp = np.asarray(camera.principal_point)
    # The strip box is centred on the disc, so its ring segment is too: the radius-aligned box lies
    # on the disc's ray, `BOX_WH[1]` rows long in frame px of radius, as wide as the segment's
    # arc through its centre.
    grid_radius = 320 * np.pi / 2  # 90° of this equidistant lens, inside the frame's corners
    offset, ray = box[:2] - pp, (uv - pp) / np.linalg.norm(uv - pp)
    assert abs(ray[0] * offset[1] - ray[1] * offset[0]) < 1.0
    assert box[3] == pytest.approx(BOX_WH[1] * grid_radius / 64, rel=0.01)
    outer = np.linalg.norm(uv - pp) + box[3] / 2  # the strip box's top row, from the disc's centre
    assert np.dot(offset, ray) + box[3] / 2 == pytest.approx(outer, abs=2.0)  # strip centroid: ±1-2 px
    assert box[2] == pytest.approx(BOX_WH[0] * 2 * np.pi / 256 * np.linalg.norm(offset), rel=0.01)
    if with_foot:
        # The model's foot (the strip box's bottom middle) is the middle of the segment's inner arc.
        expected = uv - ray * box[3] / 2
        np.testing.assert_allclose(detections.foot_px[0], expected, atol=2.0)
    else:
        np.testing.assert_allclose(detections.foot_px[0], foot_points(box[None], pp)[0])
    np.testing.assert_allclose(detections.position_m[0], camera.pixels_to_floor(detections.foot_px)[0])


def test_a_planned_model_needs_a_dynamic_input(tmp_path: Path) -> None:
    fixed = save_polar_double(tmp_path / "fixed.onnx", metadata={**METADATA, "fishloc.view_planned": "1"})
    with pytest.raises(ModelError, match="dynamic height and width"):
        OnnxModel(fixed, SessionThreads(1))
    with pytest.raises(ModelError, match="view_planned must be 0 or 1"):
        odd = {**METADATA, "fishloc.view_planned": "yes"}
        OnnxModel(save_polar_double(tmp_path / "odd.onnx", metadata=odd), SessionThreads(1))


def test_a_planned_model_with_one_band_places_the_person_as_its_strip(tmp_path: Path) -> None:
    # One band at the trained scale is the fixed strip: the same box, whichever contract it came by.
    fixed_model = OnnxModel(save_polar_double(tmp_path / "fixed.onnx"), SessionThreads(1))
    fixed = Pipeline(fixed_model, PipelineConfig())
    planned_model = OnnxModel(save_polar_double(tmp_path / "planned.onnx", planned=True), SessionThreads(1))
    assert planned_model.info.planned
    one_band = dataclasses.replace(DEFAULT_VIEW, scales=(1.0,))
    planned = Pipeline(planned_model, PipelineConfig(view=one_band))
    camera = camera_from_dict(CAMERA)
    plan = planned.plan(camera)
    assert plan is not None and plan.canvas_wh == (WIDTH + OVERLAP, 64)
    data, _ = _person_frame(camera, (1.5, 0.8))
    np.testing.assert_allclose(planned.detect(data, camera).detections.cxcywh,
                               fixed.detect(data, camera).detections.cxcywh, atol=1e-3)


def test_a_planned_outer_band_maps_its_boxes_to_the_frame(tmp_path: Path) -> None:
    # Two bands: the inner one reaches a little past the split, the outer one (1.5x) holds the far
    # person alone; its box comes back on the person's ray, as long as the band's rows say.
    path = save_polar_double(tmp_path / "planned.onnx", foot=True, planned=True)
    model = OnnxModel(path, SessionThreads(1))
    view = dataclasses.replace(DEFAULT_VIEW, band_margin=0.3, max_pixels=4_000_000)
    pipeline = Pipeline(model, PipelineConfig(view=view))
    camera = camera_from_dict(CAMERA)
    plan = pipeline.plan(camera)
    assert plan is not None and len(plan.bands) == 2
    inner, outer = plan.bands
    angle = 2 * np.pi / 3 / 2  # the middle of the outer band's first piece
    radius = (inner.radius_px + outer.radius_px) / 2  # beyond the inner band's reach
    pp = np.asarray(camera.principal_point)
    uv = pp + radius * np.array([np.cos(angle), np.sin(angle)])
    xy_m = camera.pixels_to_floor(uv[None])[0]
    data, uv = _person_frame(camera, (float(xy_m[0]), float(xy_m[1])))
    detections = pipeline.detect(data, camera).detections
    assert len(detections.scores) == 1
    box = detections.cxcywh[0]
    offset, ray = box[:2] - pp, (uv - pp) / np.linalg.norm(uv - pp)
    assert abs(ray[0] * offset[1] - ray[1] * offset[0]) < 1.0
    rows_per_px = plan.grids[-1].px_per_radius_px
    assert box[3] == pytest.approx(BOX_WH[1] / rows_per_px, rel=0.01)
    assert np.dot(offset, ray) == pytest.approx(np.linalg.norm(uv - pp), abs=2.0)
    np.testing.assert_allclose(detections.foot_px[0], uv - ray * box[3] / 2, atol=2.0)


def test_a_view_of_two_by_two_samples_a_px_places_the_person_as_one_sample_does(tmp_path: Path) -> None:
    # `ViewPlanConfig.unwrap_samples`: the same canvas, each px the mean of 2 x 2 samples, from a
    # frame decoded twice as large along the radius
    path = save_polar_double(tmp_path / "planned.onnx", foot=True, planned=True)
    model = OnnxModel(path, SessionThreads(1))
    sampled_view = dataclasses.replace(DEFAULT_VIEW, unwrap_samples=2)
    one, sampled = (Pipeline(model, PipelineConfig(view=view)) for view in (DEFAULT_VIEW, sampled_view))
    camera = camera_from_dict(CAMERA)
    plan = one.plan(camera)
    assert plan is not None and plan == sampled.plan(camera)
    bands = max(grid.px_per_radius_px for grid in plan.grids)
    assert min_decoded_side(model.info, camera, sampled_view) >= math.ceil(1024 * 2 * bands) > (
        min_decoded_side(model.info, camera, DEFAULT_VIEW))
    data, _ = _person_frame(camera, (1.5, 0.8))
    found, found_sampled = (pipeline.detect(data, camera).detections for pipeline in (one, sampled))
    assert len(found.scores) == len(found_sampled.scores) == 1
    np.testing.assert_allclose(found_sampled.cxcywh, found.cxcywh, atol=1.5)
    np.testing.assert_allclose(found_sampled.foot_px, found.foot_px, atol=1.5)


def test_a_camera_record_plans_its_own_view_within_the_limit(tmp_path: Path) -> None:
    # The server's budget gives this camera one band; its record's own budget, two (the evaluation's
    # runner and the service's pipeline alike); over the limit, the record is planned at the limit.
    path = save_polar_double(tmp_path / "planned.onnx", foot=True, planned=True)
    model = OnnxModel(path, SessionThreads(1))
    view = dataclasses.replace(DEFAULT_VIEW, max_pixels=40_000)  # the double's strip is 64 rows
    pipeline = Pipeline(model, PipelineConfig(view=view, max_camera_view_pixels=90_000))
    server, own = camera_from_dict(CAMERA), camera_from_dict({**CAMERA, "max_view_pixels": 80_000})
    server_plan, own_plan = pipeline.plan(server), pipeline.plan(own)
    assert server_plan is not None and own_plan is not None
    assert server_plan.layout == "1band+nadir" and own_plan.layout == "2band+nadir"
    assert server_plan.pixels <= 40_000 < own_plan.pixels == server_plan.wanted_pixels <= 80_000
    assert pipeline.admit(own) == own_plan
    over = camera_from_dict({**CAMERA, "max_view_pixels": 90_001})
    with pytest.raises(ViewBudgetError, match="over this server's limit 90000"):
        pipeline.admit(over)
    assert pipeline.view_config(over).max_pixels == 90_000  # a stored record: planned at the limit
    data, _ = _person_frame(server, (1.5, 0.8))
    rgb = cv2.cvtColor(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    runner = ModelRunner(model, view=view)
    layouts = [mapping_layout(o.mapping) for o in runner.outputs([rgb, rgb], [server, own])]
    assert layouts == ["1band+nadir", "2band+nadir"]
    found = [len(pipeline.detect(data, camera).detections.scores) for camera in (server, own)]
    assert found == [1, 1]


@pytest.mark.parametrize(("camera_change", "max_pixels", "reason"), [
    ({}, 4096, "budget of 4096 px"),
    ({"focal_px": [4.0, 4.0]}, 1_000_000, "leaves no view"),
])
def test_an_unplannable_camera_is_a_frame_error(tmp_path: Path, camera_change: dict[str, object],
                                                max_pixels: int, reason: str) -> None:
    model = OnnxModel(save_polar_double(tmp_path / "planned.onnx", planned=True), SessionThreads(1))
    pipeline = Pipeline(model, PipelineConfig(view=dataclasses.replace(DEFAULT_VIEW, max_pixels=max_pixels)))
    camera = camera_from_dict({**CAMERA, **camera_change})
    data, _ = _person_frame(camera_from_dict(CAMERA), (1.0, 1.0))
    with pytest.raises(FrameError) as refused:
        pipeline.detect(data, camera)
    assert refused.value.code == "view_unplannable" and reason in refused.value.message


def test_the_nadir_view_reads_a_person_below_the_lens_as_an_upright_crop(tmp_path: Path) -> None:
    # The double's box lands on the bright disc in the nadir view too; that box comes back centred on
    # the disc, radius-aligned, its foot halfway from its side nearest the principal point to its centre.
    from contract.views import upright_to_radius_aligned

    path = save_polar_double(tmp_path / "planned.onnx", foot=True, planned=True)
    model = OnnxModel(path, SessionThreads(1))
    camera = camera_from_dict(CAMERA)
    with_nadir = Pipeline(model, PipelineConfig(view=dataclasses.replace(DEFAULT_VIEW, scales=(1.0,))))
    plan = with_nadir.plan(camera)
    assert plan is not None and plan.nadir is not None
    nadir = plan.nadir
    data, uv = _person_frame(camera, (0.3, 0.2))  # 38 px from the principal point, inside its owned disc
    pp = np.asarray(camera.principal_point)
    assert np.linalg.norm(uv - pp) < nadir.owned_px
    found = with_nadir.detect(data, camera).detections
    at = (uv - (pp - nadir.half_px)) * nadir.scale - 0.5  # the disc in the nadir view's own px
    half_wh = np.array(BOX_WH) / 2
    expected = upright_to_radius_aligned(nadir, np.concatenate([at - half_wh, at + half_wh])[None])[0]
    from_nadir = [i for i, box in enumerate(found.cxcywh)
                  if np.linalg.norm(box[:2] - uv) < 3.0 and np.allclose(box[2:], expected[2:], rtol=0.05)]
    assert len(from_nadir) == 1
    box = found.cxcywh[from_nadir[0]]
    side = foot_points(box[None], pp)[0]
    np.testing.assert_allclose(found.foot_px[from_nadir[0]], (side + box[:2]) / 2, atol=1e-6)
    # without the nadir view the strip alone reads the frame: no box of that size
    strip_only = Pipeline(model, PipelineConfig(view=dataclasses.replace(DEFAULT_VIEW, scales=(1.0,),
                                                                         nadir_fraction=None)))
    strip_boxes = strip_only.detect(data, camera).detections.cxcywh
    assert len(strip_boxes) and all(not np.allclose(b[2:], box[2:], rtol=0.1) for b in strip_boxes)


def test_nadir_view_boxes_are_kept_only_inside_its_owned_disc_and_clear_of_its_edges() -> None:
    from contract import RawOutputs, merge_outputs
    from contract.views import PlannedInput
    from fisheye.view_plan import ViewReference, plan_view

    camera = camera_from_dict(CAMERA)
    plan = plan_view(camera, ViewReference(rows=64, turn_columns=WIDTH, overlap=OVERLAP),
                     dataclasses.replace(DEFAULT_VIEW, scales=(1.0,)))
    nadir = plan.nadir
    assert nadir is not None
    mapping = PlannedInput(plan)
    mid, side = (nadir.side - 1) / 2, nadir.side  # input px centres at integers
    local = np.array([[mid - 4, mid - 4, mid + 4, mid + 4],  # centred on the principal point: kept
                      [0.0, mid - 4, 8.0, mid + 4],  # on the crop's edge: a cut person, dropped
                      [side - 12, side - 12, side - 4, side - 4]], dtype=np.float32)  # past the owned disc
    canvas = RawOutputs(np.array([[10, 10, 20, 30]], np.float32), np.array([0.5], np.float32),
                        np.array([[15, 30]], np.float32))
    merged = merge_outputs([canvas, RawOutputs(local, np.array([0.9, 0.8, 0.7], np.float32),
                                               np.zeros((3, 2), np.float32))], mapping)
    assert merged.scores.tolist() == pytest.approx([0.9, 0.8, 0.7, 0.5])
    np.testing.assert_allclose(merged.boxes[0], local[0] + [nadir.column, 0, nadir.column, 0])
    assert mapping.usable(merged.boxes.astype(np.float64)).tolist()[:3] == [True, False, False]
    assert mapping.box_side_feet(merged.boxes.astype(np.float64)).tolist() == [True, True, True, False]
    centre = mapping.boxes_to_frame(merged.boxes[:1].astype(np.float64))[0, :2]
    np.testing.assert_allclose(centre, camera.principal_point, atol=1e-6)
    with pytest.raises(ValueError, match="3 outputs"):
        merge_outputs([canvas, canvas, canvas], mapping)


@pytest.mark.parametrize(("points", "found"), [
    ('{"1band+nadir": {"min_score": 0.95, "nms_iou": 0.5}}', False),  # its view's own threshold, above 0.9
    ('{"2band+nadir": {"min_score": 0.95, "nms_iou": 0.5}}', True),  # another view's: the model's 0.3
])
def test_a_view_runs_at_its_own_operating_point(tmp_path: Path, points: str, found: bool) -> None:
    from contract import ModelRunner

    metadata = {**METADATA, "fishloc.view_operating_points": points}
    path = save_polar_double(tmp_path / "planned.onnx", planned=True, metadata=metadata)
    model = OnnxModel(path, SessionThreads(1))
    view = dataclasses.replace(DEFAULT_VIEW, scales=(1.0,))  # one band and the nadir view
    pipeline = Pipeline(model, PipelineConfig(view=view))
    camera = camera_from_dict(CAMERA)
    plan = pipeline.plan(camera)
    assert plan is not None and plan.layout == "1band+nadir"
    data, _ = _person_frame(camera, (1.5, 0.8))
    assert bool(len(pipeline.detect(data, camera).detections.scores)) is found
    # a caller's threshold wins
    assert len(pipeline.detect(data, camera, min_score=0.5).detections.scores) > 0
    # evaluation reads the same point through the runner, and records it with the detections
    import cv2
    rgb = cv2.cvtColor(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    runner = ModelRunner(model, view=view)
    detections = runner.detect([rgb], [camera], 0.05)[0]
    expected = model.info.point_for("1band+nadir")
    assert detections.view_point == expected and len(detections.scores) > 0
    assert pipeline.point(plan.layout) == expected


@pytest.mark.parametrize("spinning", ["off", "alone", "on"])
def test_the_nadir_view_runs_without_the_foot_branch(tmp_path: Path, spinning: str) -> None:
    # `run_boxes` answers the boxes and scores of `run` and no foot (a second session of the graph
    # cut to them, whether or not the pools spin); merged with the canvas's outputs, the nadir
    # view's candidates get finite places for feet they never use.
    from contract import merge_outputs, run_view
    from contract.views import PlannedInput

    path = save_polar_double(tmp_path / "planned.onnx", foot=True, planned=True)
    model = OnnxModel(path, SessionThreads(1, spinning=spinning))
    image = np.zeros((64, 96, 3), dtype=np.uint8)
    image[20:30, 40:50] = 255
    # the cut graph's session is made on first use, in the session set the run goes to (the
    # spinning one under "alone", with nothing else in flight)
    sessions = model._spinning if spinning == "alone" else model._sessions
    assert sessions is not None and sessions._boxes_session is None and sessions._cut is not None
    full, boxes_only = model.run(image), model.run_boxes(image)
    assert sessions._boxes_session is not None and sessions._cut is None
    assert boxes_only.foot is None and full.foot is not None
    np.testing.assert_array_equal(boxes_only.boxes, full.boxes)
    np.testing.assert_array_equal(boxes_only.scores, full.scores)
    pipeline = Pipeline(model, PipelineConfig(view=dataclasses.replace(DEFAULT_VIEW, scales=(1.0,))))
    camera = camera_from_dict(CAMERA)
    plan = pipeline.plan(camera)
    assert plan is not None and plan.nadir is not None
    mapping = PlannedInput(plan)
    side = plan.nadir.side
    merged = run_view(model, [np.zeros((plan.canvas_wh[1], plan.canvas_wh[0], 3), np.uint8),
                              np.zeros((side, side, 3), np.uint8)], mapping)
    assert merged.foot is not None and np.isfinite(merged.foot).all() and len(merged.scores) == 2
    assert merge_outputs([full, boxes_only], mapping).foot is not None


def test_warm_up_makes_the_nadir_session_only_where_the_budget_gives_the_view(tmp_path: Path) -> None:
    path = save_polar_double(tmp_path / "planned.onnx", foot=True, planned=True)
    for nadir_fraction, made in ((None, False), (0.2, True)):
        model = OnnxModel(path, SessionThreads(1, spinning="alone"))
        shapes: list[tuple[int, ...]] = []
        run_in = model._run_in

        def recording(session: object, outputs: list[str], images: np.ndarray,
                      run_in: Callable[..., list[np.ndarray]] = run_in,
                      shapes: list[tuple[int, ...]] = shapes) -> list[np.ndarray]:
            if outputs == ["boxes", "scores"]:
                shapes.append(images.shape)
            return run_in(session, outputs, images)

        model._run_in = recording  # type: ignore[method-assign]
        view = dataclasses.replace(DEFAULT_VIEW, nadir_fraction=nadir_fraction)
        Pipeline(model, PipelineConfig(view=view)).warm_up(runs=1)
        # both session sets of the "alone" policy are warmed, each at the nadir view's own size
        assert model._spinning is not None
        for sessions in (model._sessions, model._spinning):
            assert (sessions._boxes_session is not None) is made
        side = nadir_side(view_reference(model.info), view)
        assert shapes == ([(1, side, side, 3)] * 2 if made else [])
