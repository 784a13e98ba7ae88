"""The planned view of a camera: bands, pieces, the canvas, budgets and refusals."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fisheye import assumed_camera, load_camera
from fisheye.view_plan import (
    ViewPlanConfig,
    ViewPlanError,
    ViewReference,
    person_sizes,
    plan_view,
    ring_radius_px,
)

DEMO = load_camera("models/demo_camera.yaml")
LARGE = ViewPlanConfig(max_pixels=4_000_000)


def test_default_budget_keeps_the_trained_strip_and_adds_the_nadir_view() -> None:
    plan = plan_view(DEMO)
    assert len(plan.bands) == 1 and plan.bands[0].scale == 1.0
    assert plan.canvas_wh == (1664 + 128, 416)
    assert plan.nadir is not None and plan.nadir.side == 384 and plan.layout == "1band+nadir"
    assert plan.pixels == 1792 * 416 + 384 * 384 <= ViewPlanConfig().max_pixels
    assert plan.cost_ratio == pytest.approx(plan.pixels / (1792 * 416))
    assert any("budget" in note for note in plan.notes)


def test_large_budget_plans_a_larger_outer_band() -> None:
    plan = plan_view(DEMO, config=LARGE)
    inner, outer = plan.bands
    assert (inner.scale, outer.scale) == (1.0, 1.5)
    assert inner.inner_radius_px == 0 and outer.inner_radius_px < inner.radius_px < outer.radius_px
    # The bands report disjoint radii that cover the whole view, split where the outer one starts
    # to be needed; the outer band shows people centred just past the split whole.
    assert inner.owned_px[1] == outer.owned_px[0]
    assert outer.inner_radius_px < outer.owned_px[0]
    assert (inner.pieces, outer.pieces) == (2, 3)
    width, height = plan.canvas_wh
    assert width % 32 == 0 and height % 32 == 0 and plan.pixels <= LARGE.max_pixels
    # Pieces sit one below another without overlapping, each inside the canvas.
    ends = [offset + grid.height for offset, grid in zip(plan.row_offsets, plan.grids, strict=True)]
    assert all(end <= start for end, start in zip(ends, plan.row_offsets[1:], strict=False))
    assert ends[-1] <= height and all(grid.strip_wh[0] <= width for grid in plan.grids)
    # Each band's pieces cover the turn once, at equal angles.
    starts = sorted(round(grid.start_rad, 9) for grid in plan.grids[2:])
    np.testing.assert_allclose(starts, [0, 2 * math.pi / 3, 4 * math.pi / 3])


def test_the_outer_band_keeps_the_trained_shape() -> None:
    plan = plan_view(DEMO, config=LARGE)
    reference = ViewReference()
    for band, grid in ((plan.bands[0], plan.grids[0]), (plan.bands[1], plan.grids[2])):
        column_scale = grid.width / reference.turn_columns
        row_scale = grid.px_per_radius_px / (reference.rows / ring_radius_px(DEMO, 90.0))
        assert column_scale == pytest.approx(band.scale)
        assert row_scale == pytest.approx(band.scale, rel=0.08)  # rows are rounded to 16


def test_an_outer_band_widened_across_the_ray_alone() -> None:
    wide = dataclasses.replace(LARGE, outer_row_scale=1.0)
    plan, alike = plan_view(DEMO, config=wide), plan_view(DEMO, config=LARGE)
    reference = ViewReference()
    inner, outer = plan.bands
    assert (outer.scale, outer.row_scale, outer.pieces) == (1.5, 1.0, 3) and inner.row_scale is None
    # Its columns are the 1.5x band's, its rows those of the trained scale over the same radii.
    grid = plan.grids[2]
    assert grid.width / reference.turn_columns == pytest.approx(1.5)
    rows_scale = grid.px_per_radius_px / (reference.rows / ring_radius_px(DEMO, 90.0))
    assert rows_scale == pytest.approx(1.0, rel=0.08)
    assert outer.rows < alike.bands[1].rows and plan.pixels < alike.pixels
    assert plan.bands[0] == alike.bands[0] and outer.owned_px == alike.bands[1].owned_px
    # The smallest person keeps the wide band's width and the trained scale's length.
    assert plan.smallest.across_px == pytest.approx(alike.smallest.across_px, rel=0.02)
    assert plan.smallest.along_px < 0.8 * alike.smallest.along_px
    assert plan.public()["bands"][1]["row_scale"] == 1.0 and "row_scale" not in plan.public()["bands"][0]


def test_a_budget_that_binds_steps_a_widened_band_down_keeping_its_rows() -> None:
    wide = ViewPlanConfig(scales=(1.0, 1.25, 1.5), max_pixels=4_000_000, outer_row_scale=1.0,
                          nadir_fraction=None)
    budget = plan_view(DEMO, config=wide).pixels - 1
    config = dataclasses.replace(wide, max_pixels=budget)
    plan = plan_view(DEMO, config=config)
    assert plan.pixels <= budget and plan.bands[1].scale == 1.25 and plan.bands[1].row_scale == 1.0
    assert any("at scale 1.25, not 1.5" in note for note in plan.notes)


def test_people_shrink_towards_the_rim() -> None:
    radii = np.linspace(300, 850, 8)  # feet up to the planned floor (θ ≤ 80°)
    along, across, distance = person_sizes(DEMO, radii, ViewPlanConfig())
    assert np.all(np.diff(distance) > 0)
    assert np.all(np.diff(across) < 0)
    assert along[-1] < along[3]


def test_a_budget_that_binds_shrinks_the_view_and_says_so() -> None:
    small = ViewPlanConfig(max_pixels=300_000)
    plan = plan_view(DEMO, config=small)
    assert plan.pixels <= 300_000
    assert plan.bands[0].scale < 1.0
    assert any("binds" in note for note in plan.notes)
    # ... and what the unbound view would take: a budget of that much plans it whole
    whole = plan_view(DEMO, config=LARGE)
    assert plan.wanted_pixels == whole.wanted_pixels == whole.pixels > 1_900_000
    assert plan_view(DEMO, config=ViewPlanConfig(max_pixels=whole.wanted_pixels)).pixels == whole.pixels
    short = plan_view(DEMO, config=ViewPlanConfig(max_pixels=whole.wanted_pixels - 1))
    assert short.layout == "2band" and any("no nadir view" in note for note in short.notes)  # it goes first
    assert plan.public()["wanted_pixels"] == whole.wanted_pixels


def test_narrowing_keeps_the_rim_band_at_its_scale_within_a_budget() -> None:
    wide = plan_view(DEMO, config=LARGE)
    budget = 1_400_000
    narrowing = ViewPlanConfig(max_pixels=budget, min_outer_fraction=0.1)
    plan = plan_view(DEMO, config=narrowing)
    assert plan.layout == "2band+nadir" and plan.pixels <= budget
    inner, outer = plan.bands
    assert outer.scale == wide.bands[1].scale == 1.5
    # the outer band starts further out than the unbound plan's, and reports the rim's people
    assert outer.owned_px[0] > wide.bands[1].owned_px[0] and outer.radius_px == wide.bands[1].radius_px
    assert inner.owned_px == (0.0, outer.owned_px[0]) and inner.radius_px > outer.owned_px[0]
    assert outer.rows < wide.bands[1].rows
    assert plan.smallest.along_px == pytest.approx(wide.smallest.along_px, rel=0.02)  # rows round to 16
    assert any("reports from" in note for note in plan.notes)
    # a wider budget lets the band reach further in; by default the band steps down to one
    wider = plan_view(DEMO, config=dataclasses.replace(narrowing, max_pixels=1_600_000))
    assert wider.bands[1].owned_px[0] < outer.owned_px[0]
    default = plan_view(DEMO, config=ViewPlanConfig(max_pixels=budget))
    assert default.layout == "1band+nadir"


def test_a_rim_band_too_thin_to_report_anyone_is_not_kept() -> None:
    plan = plan_view(DEMO, config=ViewPlanConfig(max_pixels=1_200_000, min_outer_fraction=0.1))
    assert plan.layout == "1band+nadir" and plan.bands[0].scale == 1.0
    assert any("at scale 1, not 1.5" in note for note in plan.notes)


def test_wide_circle_reaches_the_frame_corners() -> None:
    # A 1696 x 1080 frame whose 180° circle is 1680 px across: cut at its top and bottom.
    camera = assumed_camera(1696, 1080).model_copy(update={"focal_px": (534.76, 534.76)})
    plan = plan_view(camera)
    assert plan.bands[-1].radius_px == pytest.approx(534.76 * math.pi / 2)
    assert any("cuts the image circle" in note for note in plan.notes)


@pytest.mark.parametrize(("update", "reason"), [
    ({"principal_point": (5000.0, 500.0)}, "outside"),
])
def test_unplannable_cameras_are_refused(update: dict[str, object], reason: str) -> None:
    camera = DEMO.model_copy(update=update)
    with pytest.raises(ViewPlanError, match=reason):
        plan_view(camera)


def test_a_budget_below_any_view_is_refused() -> None:
    with pytest.raises(ViewPlanError, match="budget"):
        plan_view(DEMO, config=ViewPlanConfig(max_pixels=4096))


@pytest.mark.parametrize("kwargs", [{"scales": ()}, {"scales": (1.5, 1.0)}, {"max_pixels": 10},
                                    {"target_along_px": 0.0}, {"person_height_m": 4.0},
                                    {"min_outer_fraction": 0.0}, {"min_outer_fraction": 1.0},
                                    {"outer_row_scale": 0.5}, {"outer_row_scale": 2.0},
                                    {"unwrap_samples": 0}, {"unwrap_samples": 5},
                                    {"nadir_min_scale": 0.0}, {"nadir_min_scale": 1.5},
                                    {"start_columns": -1.0}, {"start_columns": 5000.0}])
def test_config_refuses_nonsense(kwargs: dict[str, object]) -> None:
    with pytest.raises(ValueError):
        ViewPlanConfig(**kwargs)  # type: ignore[arg-type]


# the nadir view

def test_a_budget_with_room_adds_the_nadir_view_beside_the_canvas() -> None:
    config = ViewPlanConfig(max_pixels=1_000_000, nadir_scale=1.5)
    plan = plan_view(DEMO, config=config)
    nadir = plan.nadir
    assert nadir is not None and len(plan.bands) == 1
    circle = DEMO.image_circle_radius_px()
    assert nadir.side == 448 and nadir.half_px == pytest.approx(0.35 * circle)
    assert nadir.owned_px == pytest.approx(0.2 * circle) and nadir.centre_px == DEMO.principal_point
    assert nadir.column == plan.canvas_wh[0] + 32  # read right of the canvas, past one stride of gap
    assert plan.pixels == 1792 * 416 + 448 * 448 <= config.max_pixels
    # its px map to the frame square it shows, edge to edge
    corners = nadir.input_to_frame(np.array([[-0.5, -0.5], [447.5, 447.5]]))
    half = np.array([[-nadir.half_px] * 2, [nadir.half_px] * 2])
    np.testing.assert_allclose(corners, np.array(DEMO.principal_point) + half)
    public = plan.public()["nadir"]
    assert isinstance(public, dict) and public["input_wh"] == [448, 448]
    assert not any("nadir" in note for note in plan.notes)


def test_a_budget_without_room_for_the_nadir_view_says_so() -> None:
    plan = plan_view(DEMO, config=ViewPlanConfig(max_pixels=800_000))
    assert plan.nadir is None and plan.public()["nadir"] is None
    assert any("no nadir view (384 x 384 px more)" in note for note in plan.notes)
    off = plan_view(DEMO, config=ViewPlanConfig(max_pixels=4_000_000, nadir_fraction=None))
    assert off.nadir is None and not any("nadir" in note for note in off.notes)


def test_start_columns_turn_every_band_by_that_many_of_its_columns() -> None:
    plain = plan_view(DEMO, config=LARGE)
    turned = plan_view(DEMO, config=dataclasses.replace(LARGE, start_columns=8))
    assert turned.canvas_wh == plain.canvas_wh and turned.bands == plain.bands
    for grid, was in zip(turned.grids, plain.grids, strict=True):
        assert grid.start_rad - was.start_rad == pytest.approx(2 * math.pi * 8 / grid.width)
        # each column shows the angle 8 columns on in the plain turn: a column roll of the same strip
        np.testing.assert_allclose(grid.column_to_angle_rad(np.arange(32)),
                                   was.column_to_angle_rad(np.arange(8, 40)))
    assert plan_view(DEMO, config=dataclasses.replace(LARGE, start_columns=0)) == plain


def test_the_nadir_view_may_be_kept_beside_a_smaller_strip() -> None:
    budget = 800_000
    kept = plan_view(DEMO, config=ViewPlanConfig(max_pixels=budget, nadir_min_scale=0.8))
    assert kept.nadir is not None and kept.layout == "1band+nadir" and kept.pixels <= budget
    (band,) = kept.bands
    assert 0.8 <= band.scale < 1.0  # the strip gave up its px, not the nadir view
    assert kept.pixels == kept.canvas_wh[0] * kept.canvas_wh[1] + 384 * 384
    assert kept.nadir.column == kept.canvas_wh[0] + 32  # beside the smaller canvas
    assert any(f"budget {budget} px binds: one band at scale" in note
               and "nadir view (384 x 384 px) kept" in note for note in kept.notes)
    # a strip that would have to shrink further than the config allows leaves the nadir view out
    strict = plan_view(DEMO, config=ViewPlanConfig(max_pixels=budget, nadir_min_scale=0.95))
    assert strict.nadir is None and strict.bands[0].scale == 1.0
    assert any("no nadir view" in note for note in strict.notes)
    # and so does one that would lose a band: two bands without the nadir view, not one with it
    whole = plan_view(DEMO, config=LARGE)
    short = plan_view(DEMO, config=ViewPlanConfig(max_pixels=whole.wanted_pixels - 1, nadir_min_scale=0.5))
    assert short.layout == "2band" and short.nadir is None
    # where both fit, the config changes nothing
    assert plan_view(DEMO, config=ViewPlanConfig(nadir_min_scale=0.5)) == plan_view(DEMO)


@pytest.mark.parametrize("kwargs", [{"nadir_fraction": 0.4, "nadir_view_fraction": 0.35},
                                    {"nadir_fraction": 0.0}, {"nadir_scale": 20.0}])
def test_an_impossible_nadir_view_is_refused(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError, match="nadir"):
        ViewPlanConfig(**kwargs)  # type: ignore[arg-type]


def test_with_the_nadir_view_the_strip_may_leave_it_the_disc() -> None:
    # Starting the strip 0.1 of the radius out saves rows (416 -> 384 for the demo camera), and
    # those saved rows can make room for the nadir view in a budget the whole strip and it overrun.
    circle = DEMO.image_circle_radius_px()
    config = ViewPlanConfig(max_pixels=900_000, nadir_strip_from=0.1, nadir_scale=1.5)
    assert plan_view(DEMO, config=dataclasses.replace(config, nadir_strip_from=None)).nadir is None
    plan = plan_view(DEMO, config=config)
    assert plan.nadir is not None and plan.layout == "1band+nadir"
    (band,) = plan.bands
    assert band.inner_radius_px == pytest.approx(0.1 * circle) and band.rows < 416
    assert plan.canvas_wh == (1792, 384) and plan.pixels == 1792 * 384 + 448 * 448 <= 900_000
    assert plan.grids[0].inner_radius_px == pytest.approx(0.1 * circle)
    # where even the trimmed strip and the nadir view do not fit, the strip is whole and alone
    tight = plan_view(DEMO, config=dataclasses.replace(config, max_pixels=800_000))
    assert tight.nadir is None and tight.bands[0].inner_radius_px == 0.0 and tight.canvas_wh == (1792, 416)
    # two bands: the inner one starts out, the outer is unchanged
    wide = plan_view(DEMO, config=dataclasses.replace(config, max_pixels=4_000_000))
    full = plan_view(DEMO, config=LARGE)
    assert wide.bands[0].inner_radius_px == pytest.approx(0.1 * circle) and wide.bands[1] == full.bands[1]


@pytest.mark.parametrize("start", [0.0, 0.35, 0.5])
def test_a_strip_start_the_nadir_view_does_not_cover_is_refused(start: float) -> None:
    with pytest.raises(ValueError, match="nadir_strip_from"):
        ViewPlanConfig(nadir_strip_from=start)


def test_the_longest_person_is_a_standing_adult_times_the_ratio_away_from_below_the_lens() -> None:
    config = ViewPlanConfig(longest_person_ratio=1.8)
    longest = plan_view(DEMO, config=config).longest_person
    assert longest is not None and plan_view(DEMO).longest_person is None
    assert plan_view(DEMO, config=config).public()["longest_person_ratio"] == 1.8
    pp = DEMO.principal_point
    feet, head = DEMO.world_to_pixels(np.array([[3.0, 0.0, 0.0], [3.0, 0.0, config.person_height_m]]))
    length = float(np.hypot(*(head - feet)))
    centre = (feet + head) / 2
    boxes = np.array([[centre[0], centre[1], 40.0, length * f] for f in (1.0, 1.7, 1.9)])
    # the demo camera looks straight down: every direction's adult is as long as this one
    found = longest.too_long(boxes, np.repeat(feet[None], 3, 0), pp)
    np.testing.assert_array_equal(found, [False, False, True])
    # within a person's height of the spot below the lens nothing is judged, however long
    near = DEMO.world_to_pixels(np.array([[1.0, 0.0, 0.0]]))
    assert not longest.too_long(np.array([[near[0, 0], near[0, 1], 40.0, 5000.0]]), near, pp)[0]
    with pytest.raises(ValueError, match="longest_person_ratio"):
        ViewPlanConfig(longest_person_ratio=0.5)
