"""A camera's view planned for a polar detector: rings of the frame, each unwrapped at its own scale.

A detector trained on one strip (`ViewReference`: `rows` for the ring of θ = 90°, `turn_columns`
per turn) finds people well in a band of sizes. In a fixed strip a person's size follows the floor
distance: big below the lens, a few pixels at the rim. The plan measures a standing adult
(`ViewPlanConfig.person_*`) wherever the floor is in view through the camera's own lens, altitude
and tilt, and cuts the frame into rings (bands): the inner ring at the trained scale, the outer at a
larger one where the person falls below the target size. Scaling both axes of a band by the same
factor keeps people's shape as the network learnt it.

Each band is unwrapped into `pieces` strips that cover equal angles (a band at 1.5x the trained
scale has 1.5x the columns per turn): pieces of every band have the same width, so they stack into
one input image (the canvas), each below the previous one with `gap_rows` rows of padding between
them. A band's strip rows map linearly to its radii (`fisheye.polar.PolarGrid` with an inner radius).

Each band reports the people centred in its own radii (the inner band those inside the split, the
outer band the rest) and shows `band_margin` standing adults' lengths past them, so a person
centred near the split is whole in the band that reports them; the detector's NMS in the frame
merges the copies of a person in the overlap columns of a band's pieces.

Below the lens the strip fails whatever its scale: a person seen from above whose box lies within
its own size of the principal point is smeared across the turn (on the validation renders, of the
33 people centred within 0.08 of the image circle's radius it found one from score 0.05, none at
the threshold). Where the budget allows,
the plan adds a **nadir view** (`NadirPiece`): the disc about the principal point as an upright
square crop of the frame, at 1.25x the strip's radial scale, a second input of the same network.
It reports the people centred within `nadir_fraction` of the image circle's radius (the strip keeps
reporting them too; the detector's NMS in the frame merges the two) and shows `nadir_view_fraction`,
so that a person centred at its edge is whole in it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fisheye.camera import (
    MAX_LONGEST_PERSON_RATIO,
    MAX_SECOND_LOOK_PIXELS,
    MIN_LONGEST_PERSON_RATIO,
    FisheyeCamera,
)
from fisheye.lens import theta_to_radius
from fisheye.polar import TWO_PI, PolarGrid

FloatArray = NDArray[np.float64]
STRIDE = 32  # the canvas's sides are multiples of the network's largest stride
# The pieces' grids, each piece's first row in the canvas, and the canvas's (width, height).
Layout = tuple[tuple[PolarGrid, ...], tuple[int, ...], tuple[int, int]]


class ViewPlanError(ValueError):
    """A camera whose view cannot be planned (circle outside the frame, a budget too small)."""


@dataclass(frozen=True)
class ViewReference:
    """The strip a model was trained on: `rows` for the radius of the ring θ = `max_theta_deg`,
    `turn_columns` per turn and `overlap` repeated columns (DESIGN.md's `polar` view)."""

    rows: int = 416
    turn_columns: int = 1664
    overlap: int = 128
    max_theta_deg: float = 90.0

    @property
    def pixels(self) -> int:
        return self.rows * (self.turn_columns + self.overlap)


MAX_SECOND_LOOK_PATCHES = 64
SECOND_LOOK_PATCH_PX = (96, 256)  # a patch's side lies within these (multiples of 32)
SECOND_LOOK_FULL_PIXELS = 12 * SECOND_LOOK_PATCH_PX[1] ** 2  # the default 12 patches, each at its largest
SECOND_LOOK_MAX_ZOOM = 4.0  # a patch's zoom over its band at most (`ViewPlanConfig.second_look_target_rows`)
# MAX_SECOND_LOOK_PIXELS (fisheye.camera, where a camera's record may set its own look): the
# MAX_SECOND_LOOK_PATCHES patches at their largest.


@dataclass(frozen=True)
class ViewPlanConfig:
    """What a plan aims at. `scales` are the band scales it may use (1.0: the trained strip), the
    smallest first; a band gets the smallest scale at which the person reaches `target_along_px`
    rows along the ray and `target_across_px` columns across it, or the largest scale."""

    person_height_m: float = 1.7
    person_width_m: float = 0.5
    target_along_px: float = 96.0
    target_across_px: float = 48.0
    scales: tuple[float, ...] = (1.0, 1.5)
    floor_theta_deg: float = 80.0  # people are planned for up to this angle from the axis (17 m at 3 m)
    # Each band shows this many standing adults' lengths (at the split) past the radii it reports,
    # so a person centred there is whole in it; None: the inner band shows the whole disc. 0.6 was
    # chosen over the whole disc on the real and rendered sets together (docs/DETECTOR.md, "Planned views").
    band_margin: float | None = 0.6
    # The trained strip (745 472 px) and the nadir view (384 x 384 px): 0.5.0's latency end to end
    # with 0.7.0's lighter foot branch (0.97-0.99x its time at 2952², 0.98x at 2048² and 1080²;
    # docs/DETECTOR.md, "A lighter foot neck"); 800 000, the strip alone, from 0.6.1 to 0.6.2.
    max_pixels: int = 900_000
    gap_rows: int = STRIDE
    # The nadir view (module docstring; docs/DETECTOR.md, "The nadir view and a faster graph"): the people it
    # reports, what it shows (fractions of the image circle's radius) and its scale over the strip's
    # radial one; None: none. 0.35 was chosen over 0.25 and 0.3 on the real and rendered sets
    # together; of the scales, 1.5 (448 px) found the most below the lens, 1.25 (384 px; recall
    # there 0.54 against 0.57 on the unseen renders, scenes4 AP50 0.451 against 0.461, Lunch3 the
    # same) is the one whose time fits the default budget's: since 0.7.0 the default.
    nadir_fraction: float | None = 0.2
    nadir_view_fraction: float = 0.35
    nadir_scale: float = 1.25
    # With a nadir view the strip (its innermost band) may start this fraction of the image circle's
    # radius out: the nadir view shows the disc within. None: the strip starts at the principal point.
    nadir_strip_from: float | None = None
    # Where the budget has no room for both the bands as planned and the nadir view, the bands may
    # shrink to leave the nadir view its px, as long as they stay as many and each keeps at least
    # this fraction of its scale; otherwise (and where None, the default) the nadir view goes, with
    # a note. Measured at 350 000-800 000 px, neither order won on the real sets over the budgets
    # (docs/DETECTOR.md, "A budget under the default"): a design, not the rule.
    nadir_min_scale: float | None = None
    # Where two bands do not fit the budget, the outer band may first keep its scale and start
    # further out (the nadir view's pixels kept aside), as long as it reports at least this
    # fraction of the view's radius; then it steps down the scales. None (the default): it steps
    # down at once. Narrowing found more of the renders' far people at 1.4M-1.6M px but not more
    # of the real frames' (docs/DETECTOR.md, "The rim band narrowed to fit a budget"): a design, not the rule.
    min_outer_fraction: float | None = None
    # The outer band's rows at this scale over the trained strip while its columns keep the band's
    # scale: the rim widened across the ray alone, where a person's width, not length, is what the
    # network misses (8 px across against 27 along at the default budget). Widened alone, the rim
    # found more of the renders' far people and lost most of the real frames' people it reports
    # (docs/DETECTOR.md, "The rim band widened across the ray alone"): a design, not the rule. None (the
    # default): the outer band is scaled alike on both axes, people keep the shape the network learnt.
    outer_row_scale: float | None = None
    # Every band's turn starts this many of its columns further round from the camera's +x axis:
    # the strip's seam, and the network's grid of cells over the people, moved by that much. A
    # person's detection depends on where the cells fall on it (a few columns moved Lunch3's AP50
    # from 0.933 to 0.736; docs/DETECTOR.md, "Real frames read at several scales"): the benchmark
    # reads the real frames over several starts. 0 (the default): the turn starts at the +x axis.
    start_columns: float = 0.0
    # Each px of the bands the mean of this many bilinear samples of the frame along each axis
    # (`fisheye.polar.PolarGrid.sampling_maps`), the frame decoded that much larger: where a band px
    # spans several frame px (across the ray at the rim) it averages them as a downscale does. With
    # 2 x 2 the shipped network, trained on one sample a px, lost on scenes4 and gained on no set
    # (docs/DETECTOR.md, "Other runtimes and an area-averaged unwrap"): a design, not the rule.
    # 1 (the default): one sample.
    unwrap_samples: int = 1
    # The second look (`contract.second_look`): up to this many of a frame's small, uncertain
    # detections seen again, each in a patch of its band at `second_look_zoom` times the band's
    # scale, where a person of 30 x 20 band px (a seated one at the rim) becomes twice that. 12
    # patches at 2x were chosen on the validation renders over 6 and 24, 1.5x and 2.5x, and with
    # the scenes4 and Lunch3 frames beside them (docs/DETECTOR.md, "A second look"). Its patches,
    # packed into one input (`contract.second_look.pack`), take at most `second_look_pixels` input px
    # with their gutters, a budget of their own beside `max_pixels`: 0 (the default) none, for the
    # default view's time is the frame's and the look costs 1.2-1.8x it (the benchmark's renders to
    # crowded real frames); `SECOND_LOOK_FULL_PIXELS`, 12 patches' px at their largest (the canvas
    # of 12 such takes more: its last patches are left out). 0 patches: none at any budget.
    # A person shorter than `second_look_target_rows` / `second_look_zoom` band rows along the ray
    # (a far one, under 24 rows) is zoomed further, to come out `second_look_target_rows` long in
    # its patch, at most `SECOND_LOOK_MAX_ZOOM` times its band: 48 was chosen on the validation
    # renders (AP_far 0.412 -> 0.432) over 40, 56 and 64 (0.409, 0.404, 0.366) and 0, a patch at
    # `second_look_zoom` whatever its person's size (docs/DETECTOR.md, "A second look").
    second_look_patches: int = 12
    second_look_zoom: float = 2.0
    second_look_pixels: int = 0
    second_look_target_rows: float = 48.0
    # A candidate whose box runs along the ray more than this many times a standing adult's length
    # with their feet at its foot point is no person (`LongestPerson`): the camera's geometry
    # bounds how long a person can come out. Judged where the floor lies at least a person's height
    # (`person_height_m`) from below the lens in every direction, up to `floor_theta_deg`; below
    # the lens a person is seen from above and the nadir view's boxes are read otherwise. 1.8 was
    # chosen over 1.6, 2.0 and 2.25 on the validation renders (AP50, then precision); it lifts the
    # unseen renders' precision 0.837 -> 0.848 but failed the real frames' rule: at an assumed
    # altitude it drops a real person, and no real false positive is overlong (docs/DETECTOR.md,
    # "A person's length bounded by the camera"): a design for calibrated cameras, not the rule.
    # None (the default): no bound.
    longest_person_ratio: float | None = None

    def __post_init__(self) -> None:
        if not self.scales or any(not (0.25 <= s <= 4.0) for s in self.scales) or (
                list(self.scales) != sorted(set(self.scales))):
            raise ValueError(f"scales must be increasing, each in [0.25, 4], got {self.scales}")
        if not (0 < self.person_height_m < 3 and 0 < self.person_width_m < 2):
            raise ValueError("person_height_m must lie in (0, 3), person_width_m in (0, 2)")
        if self.target_along_px <= 0 or self.target_across_px <= 0:
            raise ValueError("targets must be positive")
        if self.max_pixels < 64 * 64:
            raise ValueError(f"max_pixels must be at least {64 * 64}, got {self.max_pixels}")
        if self.nadir_fraction is not None and not (
                0 < self.nadir_fraction < self.nadir_view_fraction <= 1 and 0.25 <= self.nadir_scale <= 8):
            raise ValueError("need 0 < nadir_fraction < nadir_view_fraction <= 1, nadir_scale in [0.25, 8]")
        if self.nadir_min_scale is not None and not 0 < self.nadir_min_scale <= 1:
            raise ValueError(f"nadir_min_scale must lie in (0, 1], got {self.nadir_min_scale}")
        if not 0 <= self.start_columns < 4096:
            raise ValueError(f"start_columns must lie in [0, 4096), got {self.start_columns}")
        if self.min_outer_fraction is not None and not 0 < self.min_outer_fraction < 1:
            raise ValueError(f"min_outer_fraction must lie in (0, 1), got {self.min_outer_fraction}")
        if self.outer_row_scale is not None and not self.scales[0] <= self.outer_row_scale <= self.scales[-1]:
            raise ValueError(f"outer_row_scale must lie within the scales {self.scales}, got "
                             f"{self.outer_row_scale}")
        looks = 0 <= self.second_look_patches <= MAX_SECOND_LOOK_PATCHES
        if not (looks and 1.0 < self.second_look_zoom <= SECOND_LOOK_MAX_ZOOM):
            raise ValueError(f"second_look_patches must lie in [0, {MAX_SECOND_LOOK_PATCHES}] and "
                             f"second_look_zoom in (1, 4], got {self.second_look_patches} and "
                             f"{self.second_look_zoom}")
        if not 0 <= self.second_look_target_rows <= SECOND_LOOK_PATCH_PX[1] / 3:
            raise ValueError(f"second_look_target_rows must lie in [0, {SECOND_LOOK_PATCH_PX[1] / 3:g}] (a "
                             f"patch spans three times its person), got {self.second_look_target_rows}")
        if not 0 <= self.second_look_pixels <= MAX_SECOND_LOOK_PIXELS:
            raise ValueError(f"second_look_pixels must lie in [0, {MAX_SECOND_LOOK_PIXELS}], got "
                             f"{self.second_look_pixels}")
        if not 1 <= self.unwrap_samples <= 4:
            raise ValueError(f"unwrap_samples must lie in [1, 4], got {self.unwrap_samples}")
        if self.longest_person_ratio is not None and not (
                MIN_LONGEST_PERSON_RATIO <= self.longest_person_ratio <= MAX_LONGEST_PERSON_RATIO):
            raise ValueError(f"longest_person_ratio must lie in [{MIN_LONGEST_PERSON_RATIO:g}, "
                             f"{MAX_LONGEST_PERSON_RATIO:g}], got {self.longest_person_ratio}")
        if self.nadir_strip_from is not None and not 0 < self.nadir_strip_from < self.nadir_view_fraction:
            raise ValueError("need 0 < nadir_strip_from < nadir_view_fraction: the nadir view must show "
                             "the disc the strip leaves out")


@dataclass(frozen=True)
class NadirPiece:
    """The disc below the lens as an upright crop: the frame's square `half_px` about
    `centre_px` (edges to edges; pixel centres at integers) resampled to `side` x `side` input px.
    It is its own input (the network's second run), read as if it stood at `column` of the canvas,
    right of the bands, so one mapping takes the outputs of both. It reports the people whose box
    centre lies within `owned_px` of the principal point."""

    centre_px: tuple[float, float]
    half_px: float
    side: int
    column: int
    owned_px: float

    @property
    def scale(self) -> float:
        """Input px per frame px."""
        return self.side / (2 * self.half_px)

    def input_to_frame(self, points: NDArray[np.floating]) -> FloatArray:
        """(N, 2) px of this input (its own columns, not the canvas's) -> (N, 2) frame px."""
        corner = np.asarray(self.centre_px, dtype=np.float64) - self.half_px  # where input px -0.5 lies
        return corner + (np.asarray(points, dtype=np.float64) + 0.5) / self.scale


@dataclass(frozen=True)
class ViewBand:
    """One ring of the frame: radii [`inner_radius_px`, `radius_px`] unwrapped at `scale` times the
    trained strip's columns (and rows, unless `row_scale` says otherwise) into `pieces` strips of
    `rows` rows."""

    inner_radius_px: float
    radius_px: float
    scale: float
    rows: int
    pieces: int
    owned_px: tuple[float, float] = (0.0, math.inf)  # feet radii whose people this band reports
    row_scale: float | None = None  # the rows' scale where it differs from the columns' one


@dataclass(frozen=True)
class SmallestPerson:
    """The smallest standing adult of the planned view, in model-input px, and where it stands."""

    along_px: float
    across_px: float
    radius_px: float
    distance_m: float


@dataclass(frozen=True)
class LongestPerson:
    """How long along the ray a person may come out, by the radius of their feet: `ratio` times the
    longest standing adult (`ViewPlanConfig.person_height_m`) over the directions of the frame,
    sampled at `radii_px` (frame px from the principal point, increasing); NaN where nothing is
    judged (below the lens, past the planned floor, off the frame)."""

    radii_px: tuple[float, ...]
    along_px: tuple[float, ...]
    ratio: float

    def too_long(self, boxes_cxcywh: NDArray[np.floating], feet_px: NDArray[np.floating],
                 principal_point: tuple[float, float]) -> NDArray[np.bool_]:
        """(N,) which of (N, 4) radius-aligned frame boxes (`h` along the ray) are longer than
        `ratio` standing adults with their feet at (N, 2) `feet_px`."""
        feet = np.asarray(feet_px, dtype=np.float64)
        radius = np.hypot(feet[:, 0] - principal_point[0], feet[:, 1] - principal_point[1])
        limit = np.interp(radius, self.radii_px, self.along_px, left=np.nan, right=np.nan) * self.ratio
        with np.errstate(invalid="ignore"):
            return np.asarray(boxes_cxcywh, dtype=np.float64)[:, 3] > limit  # NaN: not judged


@dataclass(frozen=True)
class ViewPlan:
    """The planned view of one camera: the grids of its pieces (frame px) and where each sits in the
    canvas (`row_offsets`), the canvas's (width, height), its bands and what it costs."""

    grids: tuple[PolarGrid, ...]
    row_offsets: tuple[int, ...]
    canvas_wh: tuple[int, int]
    bands: tuple[ViewBand, ...]
    smallest: SmallestPerson
    reference_pixels: int
    notes: tuple[str, ...] = field(default_factory=tuple)
    nadir: NadirPiece | None = None
    # Input px of the view the camera's people ask for (every band at the scale it wants, and the
    # nadir view), before any budget: a budget of at least this plans it whole.
    wanted_pixels: int = 0
    # The second look's patches at most (`ViewPlanConfig.second_look_patches`; 0: none), their
    # zoom over their band's scale, and the input px they may take in all; a smaller person's patch
    # zoomed to bring it to `second_look_target_rows` rows (`SECOND_LOOK_MAX_ZOOM` at most).
    second_look_patches: int = 0
    second_look_zoom: float = 2.0
    second_look_pixels: int = 0
    second_look_target_rows: float = 0.0
    longest_person: LongestPerson | None = None  # `ViewPlanConfig.longest_person_ratio`; None: no bound

    def second_look_zoom_for(self, along_rows: float) -> float:
        """The zoom of a patch about a person `along_rows` band rows long: `second_look_zoom`, or
        more for a person so short that it would come out under `second_look_target_rows`."""
        wanted = self.second_look_target_rows / max(along_rows, 1e-6)
        return max(self.second_look_zoom, min(wanted, SECOND_LOOK_MAX_ZOOM))

    @property
    def owned_px(self) -> tuple[tuple[float, float], ...]:
        """Per piece, the feet radii (frame px) whose detections it reports: each person once."""
        return tuple(band.owned_px for band in self.bands for _ in range(band.pieces))

    @property
    def pixels(self) -> int:
        """Input px of every run: the canvas and the nadir view."""
        return self.canvas_wh[0] * self.canvas_wh[1] + (self.nadir.side ** 2 if self.nadir else 0)

    @property
    def cost_ratio(self) -> float:
        """Input pixels against the trained strip's (the network's cost is about proportional)."""
        return self.pixels / self.reference_pixels

    @property
    def layout(self) -> str:
        """What the plan runs, as a model names the views it has an operating point for
        (`contract.metadata.ModelInfo.view_points`): `1band`, `2band`, each `+nadir` with one and
        `+look` with the second look."""
        return view_layout(len(self.bands), self.nadir is not None, self.second_look_patches > 0)

    def public(self) -> dict[str, object]:
        """The plan as `GET /v1/cameras/{id}` reports it."""
        return {
            "input_wh": list(self.canvas_wh), "pixels": self.pixels, "wanted_pixels": self.wanted_pixels,
            "cost_ratio": round(self.cost_ratio, 3), "layout": self.layout,
            "bands": [{"inner_radius_px": round(b.inner_radius_px, 1), "radius_px": round(b.radius_px, 1),
                       "scale": b.scale, "rows": b.rows, "pieces": b.pieces,
                       **({} if b.row_scale is None else {"row_scale": b.row_scale})} for b in self.bands],
            "smallest_person": {"along_px": round(self.smallest.along_px, 1),
                                "across_px": round(self.smallest.across_px, 1),
                                "radius_px": round(self.smallest.radius_px, 1),
                                "distance_m": round(self.smallest.distance_m, 2)},
            "nadir": None if self.nadir is None else {
                "input_wh": [self.nadir.side, self.nadir.side], "half_px": round(self.nadir.half_px, 1),
                "scale": round(self.nadir.scale, 4), "owned_radius_px": round(self.nadir.owned_px, 1)},
            # the look's cost at most: its one run's px against the trained strip's, as `cost_ratio`
            "second_look": None if not self.second_look_patches else {
                "max_patches": self.second_look_patches, "zoom": self.second_look_zoom,
                "target_rows": self.second_look_target_rows,
                "max_zoom": SECOND_LOOK_MAX_ZOOM if self.second_look_target_rows else self.second_look_zoom,
                "patch_px": list(SECOND_LOOK_PATCH_PX), "max_pixels": self.second_look_pixels,
                "max_cost_ratio": round(self.second_look_pixels / self.reference_pixels, 3)},
            "longest_person_ratio": None if self.longest_person is None else self.longest_person.ratio,
            "notes": list(self.notes),
        }


def view_layout(bands: int, nadir: bool, second_look: bool = False) -> str:
    """The name of a plan of `bands` bands, with or without the nadir view, with or without the
    second look (`ViewPlan.layout`): `1band`, `2band+nadir`, `1band+nadir+look`, ..."""
    return f"{bands}band" + ("+nadir" if nadir else "") + ("+look" if second_look else "")


def _ceil_to(value: float, step: int) -> int:
    return max(step, math.ceil(value / step - 1e-9) * step)


def ring_radius_px(camera: FisheyeCamera, theta_deg: float) -> float:
    """Frame px from the principal point to the ring θ = `theta_deg` (the lens's mean focal)."""
    focal = (camera.focal_px[0] + camera.focal_px[1]) / 2
    return focal * float(theta_to_radius(np.asarray([math.radians(theta_deg)]), camera.kb)[0])


def farthest_corner_px(camera: FisheyeCamera) -> float:
    """Frame px from the principal point to the frame's farthest corner."""
    width, height = camera.image_size
    u0, v0 = camera.principal_point
    return max(math.hypot(u - u0, v - v0) for u in (-0.5, width - 0.5) for v in (-0.5, height - 0.5))


def _standing_adults(camera: FisheyeCamera, radii_px: FloatArray, config: ViewPlanConfig, directions: int
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """For feet at (R,) frame radii along each of `directions` rays: a standing adult's extent along
    the ray (frame px) and across it (radians of screen angle), and the floor distance (m), each
    (R, D); NaN off the frame, past the horizon or past `floor_theta_deg`."""
    u0, v0 = camera.principal_point
    width, height = camera.image_size
    angles = np.arange(directions) * TWO_PI / directions
    feet = np.stack([u0 + radii_px[:, None] * np.cos(angles), v0 + radii_px[:, None] * np.sin(angles)], -1)
    flat = feet.reshape(-1, 2)
    inside = (flat[:, 0] >= -0.5) & (flat[:, 0] <= width - 0.5) & (flat[:, 1] >= -0.5) & (
        flat[:, 1] <= height - 0.5)
    floor = camera.pixels_to_floor(flat)  # (R D, 2) m, NaN past the horizon
    distance = np.hypot(floor[:, 0], floor[:, 1])
    altitude, tall = camera.altitude_m, config.person_height_m
    if altitude > tall:
        head_xyz = np.concatenate([floor, np.full((len(floor), 1), tall)], axis=1)
        head = camera.world_to_pixels(head_xyz)
        along = np.hypot(*(head - flat).T)
    else:  # a camera below head height: the body runs out of the image, its lower part counts
        along = np.full(len(flat), np.inf)
    across = 2 * np.arctan2(config.person_width_m / 2, np.maximum(distance, 1e-6))
    theta = np.arctan2(distance, camera.altitude_m)
    beyond = theta > math.radians(config.floor_theta_deg)
    bad = ~inside | ~np.isfinite(distance) | ~np.isfinite(along) | beyond
    along, across, distance = (np.where(bad, np.nan, a).reshape(len(radii_px), directions)
                               for a in (along, across, distance))
    return along, across, distance


def person_sizes(camera: FisheyeCamera, radii_px: FloatArray, config: ViewPlanConfig, directions: int = 24
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """For feet at (R,) frame radii: the smallest over `directions` rays of a standing adult's extent
    along the ray (frame px) and across it (radians of screen angle), and the largest floor distance
    (m); NaN where no ray in the frame has a floor point at that radius."""
    along, across, distance = _standing_adults(camera, radii_px, config, directions)
    with np.errstate(all="ignore"):
        seen = ~np.all(np.isnan(along), axis=1)
        return (np.where(seen, np.nanmin(np.where(np.isnan(along), np.inf, along), axis=1), np.nan),
                np.where(seen, np.nanmin(np.where(np.isnan(across), np.inf, across), axis=1), np.nan),
                np.where(seen, np.nanmax(np.where(np.isnan(distance), -np.inf, distance), axis=1), np.nan))


def longest_person(camera: FisheyeCamera, top_px: float, config: ViewPlanConfig, samples: int = 128,
                   directions: int = 24) -> LongestPerson | None:
    """The bound `ViewPlanConfig.longest_person_ratio` sets on `camera`'s detections out to `top_px`
    frame px from the principal point; None where the config sets none."""
    if config.longest_person_ratio is None:
        return None
    radii = np.linspace(0.0, top_px, samples)
    along, _, distance = _standing_adults(camera, radii, config, directions)
    with np.errstate(all="ignore"):
        # below the lens in any direction the person is seen from above: nothing judged there
        near = np.any(distance < config.person_height_m, axis=1)
        seen = ~np.all(np.isnan(along), axis=1) & ~near
        longest = np.where(seen, np.nanmax(np.where(np.isnan(along), -np.inf, along), axis=1), np.nan)
    return LongestPerson(tuple(float(r) for r in radii), tuple(float(a) for a in longest),
                         config.longest_person_ratio)


def _needed_scale(along_px: FloatArray, across_rad: FloatArray, rows_per_px: float,
                  reference: ViewReference, config: ViewPlanConfig) -> FloatArray:
    """(R,) the scale over the trained strip at which the person reaches both targets."""
    along_rows = along_px * rows_per_px
    across_columns = across_rad * reference.turn_columns / TWO_PI
    return np.maximum(config.target_along_px / along_rows, config.target_across_px / across_columns)


def _layout(camera: FisheyeCamera, bands: list[ViewBand], reference: ViewReference, config: ViewPlanConfig
            ) -> Layout:
    """Pieces of every band, stacked into one canvas of equal-width pieces."""
    base = min(b.scale for b in bands)
    piece_columns = reference.turn_columns * base / min(b.pieces for b in bands)
    canvas_w = _ceil_to(piece_columns + reference.overlap, STRIDE)
    overlap = canvas_w - round(piece_columns)
    pp = (float(camera.principal_point[0]), float(camera.principal_point[1]))
    grids: list[PolarGrid] = []
    offsets: list[int] = []
    row = 0
    for band in bands:
        turn = round(piece_columns) * band.pieces
        for k in range(band.pieces):
            grids.append(PolarGrid(principal_point=pp, radius_px=band.radius_px, height=band.rows, width=turn,
                                   overlap=min(overlap, turn),
                                   start_rad=TWO_PI * (k / band.pieces + config.start_columns / turn),
                                   inner_radius_px=band.inner_radius_px, span=round(piece_columns)))
            offsets.append(row)
            row += band.rows + config.gap_rows
    canvas_h = _ceil_to(row - config.gap_rows, STRIDE)
    return tuple(grids), tuple(offsets), (canvas_w, canvas_h)


def _band(start_px: float, end_px: float, scale: float, rows_per_px: float,
          owned_px: tuple[float, float] = (0.0, math.inf), row_scale: float | None = None) -> ViewBand:
    """The ring [`start_px`, `end_px`] at `scale` times the trained strip, its rows at `row_scale`
    where given and below `scale` (rows rounded up to 16)."""
    row_scale = None if row_scale is None or row_scale >= scale else row_scale
    rows = _ceil_to((row_scale or scale) * rows_per_px * (end_px - start_px), STRIDE // 2)
    return ViewBand(start_px, end_px, scale, rows, 1, owned_px, row_scale)


def _bands(camera: FisheyeCamera, radii: FloatArray, need: FloatArray, seen: NDArray[np.bool_], top: float,
           rows_per_px: float, config: ViewPlanConfig) -> list[ViewBand]:
    """One band at the smallest scale, or two when people at the rim need more than it: the outer
    band at the smallest scale that brings them to the targets (or the largest)."""
    small = config.scales[0]
    # The rim part where people fall below the targets at the smallest scale; below the lens a
    # person seen from above is short along the ray but large across, and stays in the inner band.
    fits = np.nonzero(seen & (need <= small))[0]
    last_fit = fits[-1] if len(fits) else -1
    beyond = np.nonzero(seen & (need > small) & (np.arange(len(radii)) > last_fit))[0]
    if len(beyond) == 0 or len(config.scales) == 1:
        return [_band(0.0, top, small, rows_per_px)]
    split = float(radii[beyond[0]])
    outer_scale = next((s for s in config.scales if s >= float(np.max(need[beyond]))), config.scales[-1])
    return _split_bands(camera, split, top, small, outer_scale, rows_per_px, config)


def _split_bands(camera: FisheyeCamera, split: float, top: float, inner_scale: float, outer_scale: float,
                 rows_per_px: float, config: ViewPlanConfig) -> list[ViewBand]:
    """The inner band reporting the people centred within `split` px, the outer band the rest.
    Each shows those centred near the split whole: `band_margin` standing adults' lengths past it
    (None: the inner band the whole disc)."""
    length = _person_length_px(camera, split, config)
    margin = length if config.band_margin is None else config.band_margin * length
    reach = top if config.band_margin is None else min(top, split + margin)
    return [_band(0.0, reach, inner_scale, rows_per_px, (0.0, split)),
            _band(max(0.0, split - margin), top, outer_scale, rows_per_px, (split, math.inf),
                  config.outer_row_scale)]


def _narrowed(camera: FisheyeCamera, bands: list[ViewBand], top: float, rows_per_px: float,
              reference: ViewReference, config: ViewPlanConfig
              ) -> tuple[list[ViewBand], Layout] | None:
    """Two bands whose outer band keeps its scale but starts further out, as far in as the budget
    allows with the nadir view's pixels kept aside (where the config has one): the rim, where people
    are smallest, keeps the scale it needs. None where no split leaving the outer band at least
    `min_outer_fraction` of the view's radius fits."""
    inner, outer = bands
    if config.min_outer_fraction is None:
        return None
    reserve = (nadir_side(reference, config) or 0) ** 2
    last = top * (1 - config.min_outer_fraction)
    if outer.owned_px[0] >= last:
        return None
    for split in np.linspace(outer.owned_px[0], last, 48)[1:]:
        narrowed = _with_pieces(_split_bands(camera, float(split), top, inner.scale, outer.scale, rows_per_px,
                                             config))
        layout = _layout(camera, narrowed, reference, config)
        if _pixels(layout) + reserve <= config.max_pixels:
            return narrowed, layout
    return None


def _within_budget(camera: FisheyeCamera, bands: list[ViewBand], top: float, rows_per_px: float,
                   reference: ViewReference, config: ViewPlanConfig, reserve: int = 0
                   ) -> tuple[list[ViewBand], Layout, list[str]]:
    """The bands (cut into pieces) and their layout within `config.max_pixels`: the outer band
    starts further out at its scale where the config asks for it (`_narrowed`), else steps down the
    scales (to one band at the smallest), then the one band shrinks; notes say where the budget
    bound. `reserve` px of the budget are kept aside (the nadir view's, where it must stay); the
    notes name the whole budget. ViewPlanError when under a quarter of the trained scale or 64 rows
    would be left."""
    budget = config.max_pixels - reserve
    notes: list[str] = []
    bands = _with_pieces(bands)
    layout = _layout(camera, bands, reference, config)
    if _pixels(layout) > budget and len(bands) == 2:
        narrowed = _narrowed(camera, bands, top, rows_per_px, reference, config)
        if narrowed is not None:
            notes.append(f"budget {config.max_pixels} px binds: the outer band at scale {bands[1].scale:g} "
                         f"reports from {narrowed[0][1].owned_px[0]:.0f} px out, not "
                         f"{bands[1].owned_px[0]:.0f}")
            return narrowed[0], narrowed[1], notes
    while _pixels(layout) > budget and len(bands) == 2:
        lower = max(s for s in config.scales if s < bands[1].scale)
        notes.append(f"budget {config.max_pixels} px binds: the outer band at scale {lower:g}, "
                     f"not {bands[1].scale:g}")
        outer = bands[1]
        if lower == bands[0].scale:  # one band again
            bands = [_band(0.0, top, lower, rows_per_px)]
        else:
            bands = [bands[0], _band(outer.inner_radius_px, outer.radius_px, lower, rows_per_px,
                                     outer.owned_px, config.outer_row_scale)]
        bands = _with_pieces(bands)
        layout = _layout(camera, bands, reference, config)
    if _pixels(layout) <= budget:
        return bands, layout, notes
    scale = bands[0].scale * math.sqrt(budget / _pixels(layout))
    while True:  # rounding to the stride may leave it a little over: shrink until it fits
        if scale < 0.25 or scale * rows_per_px * top < 2 * STRIDE:  # fewer rows show nobody
            raise ViewPlanError(f"a budget of {config.max_pixels} px leaves under a quarter of the trained "
                                f"scale or under {2 * STRIDE} rows for this camera (it needs "
                                f"{_pixels(_layout(camera, _with_pieces(bands), reference, config))} px "
                                f"at scale {bands[0].scale:g})")
        shrunk = [_band(0.0, top, scale, rows_per_px)]
        layout = _layout(camera, shrunk, reference, config)
        if _pixels(layout) <= budget:
            notes.append(f"budget {config.max_pixels} px binds: one band at scale {scale:.2f}")
            return shrunk, layout, notes
        scale *= 0.97


def _pixels(layout: tuple[object, object, tuple[int, int]]) -> int:
    return layout[2][0] * layout[2][1]


def plan_view(camera: FisheyeCamera, reference: ViewReference | None = None,
              config: ViewPlanConfig | None = None) -> ViewPlan:
    """The view of `camera`'s frames (the camera at the frames' size) for a model trained on
    `reference` (default: 0.2's strip), planned with `config` (default: `ViewPlanConfig()`).
    ViewPlanError when no view can be made."""
    reference = reference or ViewReference()
    config = config or ViewPlanConfig()
    width, height = camera.image_size
    u0, v0 = camera.principal_point
    if not (-0.5 <= u0 <= width - 0.5 and -0.5 <= v0 <= height - 0.5):
        raise ViewPlanError(f"the principal point ({u0:g}, {v0:g}) lies outside the {width} x {height} frame")
    ring = ring_radius_px(camera, reference.max_theta_deg)
    top = min(ring_radius_px(camera, min(reference.max_theta_deg, camera.theta_max_deg)),
              farthest_corner_px(camera))
    if not (math.isfinite(top) and top >= 8):
        raise ViewPlanError(f"the image circle ({top:.1f} px) leaves no view of the floor")
    rows_per_px = reference.rows / ring  # the trained strip's rows per frame px of radius
    radii = np.linspace(0.02 * top, top, 96)
    along, across, distance = person_sizes(camera, radii, config)
    seen = np.isfinite(along)
    if not seen.any():
        raise ViewPlanError("no floor point of the frame lies in view of the lens")
    need = np.where(seen, _needed_scale(along, across, rows_per_px, reference, config), 0.0)
    wanted = _bands(camera, radii, need, seen, top, rows_per_px, config)
    wanted_pixels = _pixels(_layout(camera, _with_pieces(wanted), reference, config)) + (
        nadir_side(reference, config) or 0) ** 2
    bands, layout, notes = _within_budget(camera, wanted, top, rows_per_px, reference, config)
    trimmed = _strip_from(bands, camera, rows_per_px, config)
    if trimmed is not None:  # with the nadir view the strip may leave it the disc: fewer rows
        trimmed_layout = _layout(camera, trimmed, reference, config)
        nadir = _nadir_piece(camera, trimmed_layout[2], reference, config)
        if nadir is not None and _pixels(trimmed_layout) + nadir.side ** 2 <= config.max_pixels:
            bands, layout = trimmed, trimmed_layout
    nadir = _nadir_piece(camera, layout[2], reference, config)
    if nadir is not None and _pixels(layout) + nadir.side ** 2 > config.max_pixels:
        beside = _beside_nadir(camera, wanted, bands, top, rows_per_px, reference, config, nadir.side)
        if beside is None:
            notes.append(f"budget {config.max_pixels} px binds: no nadir view ({nadir.side} x {nadir.side} "
                         f"px more); people below the lens are read from the strip alone")
            nadir = None
        else:
            bands, layout, notes = beside
            nadir = _nadir_piece(camera, layout[2], reference, config)
    grids, offsets, canvas = layout
    smallest = _smallest(bands, radii, (along, across, distance), rows_per_px, reference, config, seen)
    if smallest.along_px < config.target_along_px or smallest.across_px < config.target_across_px:
        notes.append(f"the smallest person ({smallest.along_px:.0f} x {smallest.across_px:.0f} px at "
                     f"{smallest.distance_m:.1f} m) is below the target {config.target_along_px:g} x "
                     f"{config.target_across_px:g} px")
    edge = min(u0 + 0.5, width - 0.5 - u0, v0 + 0.5, height - 0.5 - v0)
    if ring > edge + 0.5:
        notes.append(f"the frame cuts the image circle ({ring:.0f} px radius, {edge:.0f} px to the nearest "
                     f"edge): the view reaches {top:.0f} px, the frame's corners included")
    look_pixels = config.second_look_pixels if config.second_look_patches else 0
    if 0 < look_pixels < SECOND_LOOK_PATCH_PX[0] ** 2:
        notes.append(f"no second look: its {look_pixels} px are fewer than a patch takes "
                     f"({SECOND_LOOK_PATCH_PX[0] ** 2})")
        look_pixels = 0
    return ViewPlan(grids, offsets, canvas, tuple(bands), smallest, reference.pixels, tuple(notes), nadir,
                    wanted_pixels, config.second_look_patches if look_pixels else 0, config.second_look_zoom,
                    look_pixels, config.second_look_target_rows, longest_person(camera, top, config))


def _beside_nadir(camera: FisheyeCamera, wanted: list[ViewBand], planned: list[ViewBand], top: float,
                  rows_per_px: float, reference: ViewReference, config: ViewPlanConfig, side: int
                  ) -> tuple[list[ViewBand], Layout, list[str]] | None:
    """The `wanted` bands within the budget less the nadir view's `side` x `side` px, where the
    config asks for it (`nadir_min_scale`) and they stay as many as the `planned` ones (those
    within the whole budget), each at least that fraction of its planned scale; None otherwise."""
    if config.nadir_min_scale is None or config.max_pixels <= side ** 2:
        return None
    try:
        bands, layout, notes = _within_budget(camera, wanted, top, rows_per_px, reference, config, side ** 2)
    except ViewPlanError:
        return None
    if len(bands) != len(planned) or any(band.scale < config.nadir_min_scale * was.scale
                                         for band, was in zip(bands, planned, strict=True)):
        return None
    return bands, layout, [f"{note}; the nadir view ({side} x {side} px) kept beside it" for note in notes]


def _strip_from(bands: list[ViewBand], camera: FisheyeCamera, rows_per_px: float, config: ViewPlanConfig
                ) -> list[ViewBand] | None:
    """The bands with the innermost starting `nadir_strip_from` of the image circle's radius out
    (None where the config asks for no nadir view or no such start)."""
    if config.nadir_fraction is None or config.nadir_strip_from is None:
        return None
    inner = bands[0]
    start = config.nadir_strip_from * camera.image_circle_radius_px()
    if start >= inner.radius_px:
        return None
    return _with_pieces([_band(start, inner.radius_px, inner.scale, rows_per_px, inner.owned_px), *bands[1:]])


def _nadir_piece(camera: FisheyeCamera, canvas_wh: tuple[int, int], reference: ViewReference,
                 config: ViewPlanConfig) -> NadirPiece | None:
    """The nadir view of `camera` (None where `config` asks for none): the square showing
    `nadir_view_fraction` of the image circle's radius about the principal point, at
    `nadir_scale` times the trained strip's rows per px of that radius (its side rounded up to the
    stride: 384 px at the defaults, whatever the camera)."""
    side = nadir_side(reference, config)
    if side is None or config.nadir_fraction is None:
        return None
    circle = camera.image_circle_radius_px()
    pp = (float(camera.principal_point[0]), float(camera.principal_point[1]))
    return NadirPiece(pp, config.nadir_view_fraction * circle, side, canvas_wh[0] + STRIDE,
                      config.nadir_fraction * circle)


def nadir_side(reference: ViewReference, config: ViewPlanConfig) -> int | None:
    """The nadir view's side in input px, the same for every camera (None where `config` asks for
    no nadir view)."""
    if config.nadir_fraction is None:
        return None
    return _ceil_to(2 * config.nadir_view_fraction * config.nadir_scale * reference.rows, STRIDE)


def may_have_nadir(reference: ViewReference, config: ViewPlanConfig) -> bool:
    """Whether a camera whose canvas is the trained strip gets the nadir view within the budget."""
    side = nadir_side(reference, config)
    return side is not None and reference.pixels + side ** 2 <= config.max_pixels


def _with_pieces(bands: list[ViewBand]) -> list[ViewBand]:
    """Each band cut into as many equal-angle pieces as its scale holds the smallest band's."""
    base = min(b.scale for b in bands)
    unit = base if all(abs(b.scale / base - round(b.scale / base)) < 1e-6 for b in bands) else base / 2
    return [dataclasses.replace(b, pieces=round(b.scale / unit)) for b in bands]


def _person_length_px(camera: FisheyeCamera, feet_radius_px: float, config: ViewPlanConfig) -> float:
    """Frame px along the ray of a standing adult whose feet lie at `feet_radius_px` (the longest
    over directions; the radius itself where no floor lies there)."""
    along, _, _ = person_sizes(camera, np.asarray([feet_radius_px]), config)
    return float(along[0]) if np.isfinite(along[0]) else feet_radius_px


def _smallest(bands: list[ViewBand], radii: FloatArray, sizes: tuple[FloatArray, FloatArray, FloatArray],
              rows_per_px: float, reference: ViewReference, config: ViewPlanConfig, seen: NDArray[np.bool_]
              ) -> SmallestPerson:
    """The smallest person over the view (against the targets), each radius read in the band of the
    largest scale that holds it."""
    along, across, distance = sizes
    scale = np.zeros(len(radii))  # along the ray, as the rows came out
    across_scale = np.zeros(len(radii))
    for band in sorted(bands, key=lambda b: b.scale):  # the largest scale last, so it wins
        inside = (radii >= band.inner_radius_px) & (radii <= band.radius_px)
        rows = band.rows / (band.radius_px - band.inner_radius_px) / rows_per_px
        scale = np.where(inside, rows, scale)
        across_scale = np.where(inside, band.scale, across_scale)  # the columns are the scale's exactly
    seen = seen & (distance >= config.person_height_m / 2)  # below the lens a person is seen from above
    along_in = np.where(seen, along * rows_per_px * scale, np.inf)
    across_in = np.where(seen, across * reference.turn_columns / TWO_PI * across_scale, np.inf)
    worst = int(np.argmin(np.minimum(along_in / config.target_along_px, across_in / config.target_across_px)))
    return SmallestPerson(float(along_in[worst]), float(across_in[worst]), float(radii[worst]),
                          float(distance[worst]))
