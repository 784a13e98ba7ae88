"""Ray casting of a scene through the fisheye model: z-buffer, person ids, cast shadows, shading.

Each group of primitives (a person, a table, a car) is intersected only with the rays of the
pixel rectangle its bounding capsule projects to, and each primitive only with the rays that pass
its bounding sphere, so a frame with 60 people stays fast. The id image of the z-buffer gives every
person's visible silhouette; rendering the person alone in its rectangle gives its unoccluded size
and its whole silhouette, what hides it ignored (the amodal silhouette a hand-drawn box takes in).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from detector.data.environment import CEILING, SKY, Background
from detector.data.primitives import (
    PATTERN_BOOKS,
    PATTERN_CHECKS,
    PATTERN_GRAIN,
    PATTERN_STRIPES,
    Primitive,
)
from detector.data.rays import RayGrid, capsule_region

FloatArray = NDArray[np.float64]
Image32 = NDArray[np.float32]

NO_PERSON = -1
SHADOW_STEP = 2


@dataclass
class Group:
    """Primitives drawn and shadowed together; `person` is the person's index or NO_PERSON."""

    primitives: list[Primitive]
    person: int = NO_PERSON

    def bound(self) -> tuple[FloatArray, FloatArray, float]:
        """A vertical capsule (bottom (3,), top (3,), radius m) holding every primitive."""
        centres = np.array([p.center for p in self.primitives])
        radii = np.array([p.radius_m for p in self.primitives])
        axis_xy = centres[:, :2].mean(axis=0)
        radius = float(np.max(np.hypot(*(centres[:, :2] - axis_xy).T) + radii))
        bottom = float(np.min(centres[:, 2] - radii)) + radius
        top = float(np.max(centres[:, 2] + radii)) - radius
        if top < bottom:
            bottom = top = (bottom + top) / 2
            radius = max(radius, float(np.max(np.abs(centres[:, 2] - bottom) + radii)))
        else:
            radius = max(radius, float(np.max(radii)))
        return np.array([*axis_xy, bottom]), np.array([*axis_xy, top]), radius


@dataclass(frozen=True)
class Lighting:
    """A directional light `direction` (3,) unit vector towards the light, its `color` (3,), the
    `ambient` (3,) light, the blur of shadow edges `shadow_softness` (px), `sky_gain` for sky."""

    direction: tuple[float, float, float]
    color: tuple[float, float, float]
    ambient: tuple[float, float, float]
    shadow_softness: float
    sky_gain: float


@dataclass(frozen=True)
class RenderOutput:
    """`image` (H, W, 3) linear RGB float32; `person_id` (H, W) int32 (NO_PERSON where none);
    `unoccluded_px` (P,) pixels each person covers when drawn alone (within the image circle);
    `whole_uv` those pixels' centres (N_p, 2) (u, v) per person: the whole silhouette."""

    image: Image32
    person_id: NDArray[np.int32]
    unoccluded_px: NDArray[np.int64]
    whole_uv: tuple[FloatArray, ...] = ()


def _pattern(prim: Primitive, points: FloatArray) -> FloatArray:
    """(N, 3) world hit points -> (N, 1) mix factor of the pattern colour."""
    mat = prim.material
    q = prim.local_points(points) / mat.period_m
    if mat.pattern == PATTERN_STRIPES:
        return (np.mod(q[:, 2], 1.0) < 0.5).astype(np.float64)[:, None]
    if mat.pattern == PATTERN_CHECKS:
        ring = np.arctan2(q[:, 1], q[:, 0]) * 4 / np.pi
        return ((np.floor(q[:, 2]) + np.floor(ring)) % 2).astype(np.float64)[:, None]
    if mat.pattern == PATTERN_GRAIN:
        return 0.35 * (0.5 + 0.5 * np.sin(q[:, 0] * 6.0 + 2.0 * np.sin(q[:, 1] * 3.0)))[:, None]
    if mat.pattern == PATTERN_BOOKS:
        # Spines 2-4 cm wide along the shelf, each its own mix of the two colours; dark shelf boards.
        spine = np.floor((q[:, 0] + q[:, 1]) * mat.period_m / 0.03)
        mix = np.mod(np.sin(spine * 12.9898 + np.floor(q[:, 2]) * 78.233) * 43758.5453, 1.0)
        board = np.mod(q[:, 2], 1.0) > 0.88
        return np.where(board, 0.0, mix)[:, None]
    return np.zeros((len(points), 1))


_GRAIN_M = 0.012  # cell size of the surface grain (fabric weave, paint, wear)
_GRAIN = 0.08  # its strength


def _grain(points: FloatArray) -> FloatArray:
    """(N, 3) world points -> (N, 1) factors around 1 from a hash of their grain cell."""
    cell = np.floor(points / _GRAIN_M)
    value = np.mod(np.sin(cell @ np.array([12.9898, 78.233, 37.719])) * 43758.5453, 1.0)
    return (1.0 + _GRAIN * (2.0 * value - 1.0))[:, None]


def _albedo(prims: list[Primitive], which: NDArray[np.intp], points: FloatArray) -> FloatArray:
    out = np.zeros((len(which), 3))
    for k in np.unique(which):
        sel = np.flatnonzero(which == k)
        prim = prims[int(k)]
        mat = prim.material
        color = np.asarray(mat.color)
        if mat.pattern:
            mix = _pattern(prim, points[sel])
            out[sel] = color * (1 - mix) + np.asarray(mat.pattern_color) * mix
            if mat.pattern == PATTERN_BOOKS:
                out[sel] *= 0.5 + 0.8 * np.abs(np.sin(mix * 91.7))
        else:
            out[sel] = color
    return out * _grain(points)


def _cast(prims: list[Primitive], origin: FloatArray, rays: FloatArray
          ) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
    """Nearest hit of `rays` (K, 3) from `origin` (3,) among `prims`: t (K,), normal, index."""
    k = len(rays)
    t_best = np.full(k, np.inf)
    n_best = np.zeros((k, 3))
    which = np.full(k, -1, np.intp)
    for index, prim in enumerate(prims):
        v = prim.center - origin
        proj = rays @ v
        cand = np.flatnonzero((float(v @ v) - proj * proj <= prim.radius_m ** 2) & (proj > -prim.radius_m))
        if cand.size == 0:
            continue
        t, n = prim.intersect(origin, rays[cand])
        closer = t < t_best[cand]
        if closer.any():
            sel = cand[closer]
            t_best[sel] = t[closer]
            n_best[sel] = n[closer]
            which[sel] = index
    return t_best, n_best, which


def _occluded(prims: list[Primitive], origins: FloatArray, direction: FloatArray) -> NDArray[np.bool_]:
    """(K,) True where the ray from each origin (K, 3) along `direction` (3,) hits a primitive."""
    blocked = np.zeros(len(origins), bool)
    directions = np.broadcast_to(direction, origins.shape)
    for prim in prims:
        v = prim.center - origins
        proj = v @ direction
        near = (np.einsum("ij,ij->i", v, v) - proj * proj <= prim.radius_m ** 2) & (proj > -prim.radius_m)
        cand = np.flatnonzero(near & ~blocked)
        if cand.size == 0:
            continue
        t, _ = prim.intersect(origins[cand], np.ascontiguousarray(directions[cand]))
        blocked[cand[np.isfinite(t)]] = True
    return blocked


@dataclass(frozen=True)
class Layer:
    """Surfaces per pixel (H, W): distance `t`, `albedo` (H, W, 3), `normal` (H, W, 3),
    `person_id`, and `drawn`: True where a group covers the background."""

    t: Image32
    albedo: Image32
    normal: Image32
    person_id: NDArray[np.int32]
    drawn: NDArray[np.bool_]

    @classmethod
    def of_background(cls, background: Background) -> Layer:
        shape = background.t.shape
        return cls(background.t, background.albedo, background.normal,
                   np.full(shape, NO_PERSON, np.int32), np.zeros(shape, bool))

    def copy(self) -> Layer:
        return Layer(self.t.copy(), self.albedo.copy(), self.normal.copy(), self.person_id.copy(),
                     self.drawn.copy())


@dataclass(frozen=True)
class StaticScene:
    """A scene's background with its fixed objects drawn, and the shadows those objects cast for
    one light direction: what every frame of the scene shares."""

    background: Background
    layer: Layer
    groups: list[Group]
    bounds: list[tuple[FloatArray, FloatArray, float]]
    light_direction: tuple[float, float, float]
    shadow: Image32


def _draw(grid: RayGrid, layer: Layer, groups: list[Group],
          bounds: list[tuple[FloatArray, FloatArray, float]], unoccluded: NDArray[np.int64],
          whole: list[FloatArray] | None = None) -> None:
    """Draw `groups` into `layer` (in place) by the z-buffer; count each person's pixels alone,
    and where `whole` is given put their (u, v) centres in it, by person."""
    cam = grid.camera
    origin = grid.origin
    for group, (a, b, radius) in zip(groups, bounds, strict=True):
        rect = capsule_region(cam, grid.world_to_camera(a), grid.world_to_camera(b), radius)
        if rect is None:
            continue
        x0, y0, x1, y1 = rect
        rays = grid.region_rays(rect)
        valid = grid.valid[y0:y1, x0:x1].ravel()
        t, n, which = _cast(group.primitives, origin, rays)
        hit = np.isfinite(t) & valid
        if group.person != NO_PERSON:
            unoccluded[group.person] = int(hit.sum())
            if whole is not None:
                hit_rows, hit_cols = np.divmod(np.flatnonzero(hit), x1 - x0)
                whole[group.person] = np.stack([hit_cols + x0, hit_rows + y0], axis=1).astype(np.float64)
        region_t = layer.t[y0:y1, x0:x1].reshape(-1)
        front = np.flatnonzero(hit & (t < region_t))
        if front.size == 0:
            continue
        points = origin + t[front, None] * rays[front]
        rows, cols = np.divmod(front, x1 - x0)
        rows += y0
        cols += x0
        layer.t[rows, cols] = t[front]
        layer.normal[rows, cols] = n[front]
        layer.albedo[rows, cols] = _albedo(group.primitives, which[front], points)
        layer.person_id[rows, cols] = group.person
        layer.drawn[rows, cols] = True


def render_static(grid: RayGrid, background: Background, groups: list[Group],
                  light_direction: tuple[float, float, float]) -> StaticScene:
    """Draw a scene's fixed objects once, with their shadows for `light_direction`."""
    layer = Layer.of_background(background).copy()
    bounds = [g.bound() for g in groups]
    _draw(grid, layer, groups, bounds, np.zeros(0, np.int64))
    light = np.asarray(light_direction, dtype=np.float64)
    shadow = _shadows(grid, layer.t, layer.normal, groups, bounds, light, None)
    return StaticScene(background, layer, groups, bounds, light_direction, shadow)


def render(grid: RayGrid, static: StaticScene, groups: list[Group], lighting: Lighting,
           n_people: int) -> RenderOutput:
    """Draw `groups` (people and other per-frame things) over a scene's static layer and light
    the result; `lighting.direction` must be the static scene's light direction."""
    if tuple(lighting.direction) != tuple(static.light_direction):
        raise ValueError("the lighting's direction differs from the static scene's")
    layer = static.layer.copy()
    unoccluded = np.zeros(n_people, np.int64)
    whole = [np.zeros((0, 2)) for _ in range(n_people)]
    bounds = [g.bound() for g in groups]
    _draw(grid, layer, groups, bounds, unoccluded, whole)
    light_dir = np.asarray(lighting.direction, dtype=np.float64)
    # Static shadows hold where the static surfaces still show; new surfaces are tested afresh.
    new = layer.drawn & ~static.layer.drawn | (layer.t < static.layer.t)
    shadow = static.shadow.copy()
    shadow[new] = 1.0
    if new.any():
        shadow = np.minimum(shadow, _shadows(grid, layer.t, layer.normal, static.groups, static.bounds,
                                             light_dir, new))
    if groups:
        shadow = np.minimum(shadow, _shadows(grid, layer.t, layer.normal, groups, bounds, light_dir, None))
    if lighting.shadow_softness > 0:
        shadow = np.asarray(cv2.GaussianBlur(shadow, (0, 0), lighting.shadow_softness), np.float32)
    normal, albedo = layer.normal, layer.albedo
    lambert = np.clip(normal @ light_dir.astype(np.float32), 0.0, 1.0)
    hemi = 0.75 + 0.25 * normal[..., 2]
    ambient = np.asarray(lighting.ambient, np.float32)
    sun = np.asarray(lighting.color, np.float32)
    light = ambient * hemi[..., None] + sun * (lambert * shadow)[..., None]
    image = albedo * light
    kind = static.background.kind
    sky = (kind == SKY) & ~layer.drawn
    image[sky] = albedo[sky] * lighting.sky_gain
    ceiling = (kind == CEILING) & ~layer.drawn
    image[ceiling] = albedo[ceiling] * ambient.mean()
    image[~grid.valid] = 0.0
    return RenderOutput(image=image, person_id=layer.person_id, unoccluded_px=unoccluded,
                        whole_uv=tuple(whole))


def _shadows(grid: RayGrid, t_buf: Image32, normal: Image32, groups: list[Group],
             bounds: list[tuple[FloatArray, FloatArray, float]], light_dir: FloatArray,
             only: NDArray[np.bool_] | None) -> Image32:
    """(H, W) float32: 0 where the light is blocked by a group, else 1 (pixels outside `only`,
    when given, are not tested and stay 1).

    Shadow rays are cast from every `SHADOW_STEP`-th pixel only and the mask is scaled up: shadow
    edges are blurred afterwards anyway, and this is the most expensive pass."""
    cam = grid.camera
    origin = grid.origin
    step = SHADOW_STEP if min(grid.shape) >= 384 else 1
    t_sub = t_buf[::step, ::step]
    only_sub = None if only is None else only[::step, ::step]
    normal_sub = normal[::step, ::step]
    rays_sub = grid.directions[::step, ::step]
    shadow = np.ones(t_sub.shape, np.float32)
    if light_dir[2] <= 0.05:
        return np.ones(grid.shape, np.float32)
    for group, (a, b, radius) in zip(groups, bounds, strict=True):
        middle = (a + b) / 2
        reach = radius + float(np.linalg.norm(b - a)) / 2
        floor_point = middle - (middle[2] / light_dir[2]) * light_dir
        rect = capsule_region(cam, grid.world_to_camera(middle), grid.world_to_camera(floor_point), reach)
        if rect is None:
            continue
        x0, y0 = rect[0] // step, rect[1] // step
        x1, y1 = -(-rect[2] // step), -(-rect[3] // step)
        t = t_sub[y0:y1, x0:x1].reshape(-1)
        usable = np.isfinite(t)
        if only_sub is not None:
            usable &= only_sub[y0:y1, x0:x1].reshape(-1)
        finite = np.flatnonzero(usable)
        if finite.size == 0:
            continue
        rays = rays_sub[y0:y1, x0:x1].reshape(-1, 3)[finite].astype(np.float64)
        points = origin + t[finite, None].astype(np.float64) * rays
        # Only points inside the shadow volume's capsule can be shadowed by this group.
        seg = floor_point - middle
        along = np.clip(((points - middle) @ seg) / max(float(seg @ seg), 1e-12), 0.0, 1.0)
        gap = points - (middle + along[:, None] * seg)
        near = np.einsum("ij,ij->i", gap, gap) <= reach * reach
        idx = finite[near]
        if idx.size == 0:
            continue
        nrm = normal_sub[y0:y1, x0:x1].reshape(-1, 3)[idx].astype(np.float64)
        starts = points[near] + 0.01 * nrm
        blocked = _occluded(group.primitives, starts, light_dir)
        if blocked.any():
            rows, cols = np.divmod(idx[blocked], x1 - x0)
            shadow[rows + y0, cols + x0] = 0.0
    if step == 1:
        return shadow
    height, width = grid.shape
    return np.asarray(cv2.resize(shadow, (width, height), interpolation=cv2.INTER_LINEAR), np.float32)
