"""3D primitives of the synthetic scenes and their ray intersections (numpy only).

Every primitive lives in the camera's floor frame (metres, z up) and answers `intersect(origins,
directions)`: rays `origins` (N, 3) or (3,) and unit `directions` (N, 3) -> distances `t` (N,) along
the ray (inf where missed) and unit outward normals (N, 3). Shapes follow iq's closed-form
intersections (boxes by slabs, capsules and capped cylinders by quadratics).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

T_MIN = 1e-4  # hits nearer than this along the ray are ignored (shadow-ray self hits)

PATTERN_PLAIN, PATTERN_STRIPES, PATTERN_CHECKS, PATTERN_GRAIN, PATTERN_BOOKS = 0, 1, 2, 3, 4


@dataclass(frozen=True)
class Material:
    """Albedo `color` (3,) linear RGB in [0, 1], an optional pattern in the primitive's local frame
    (`pattern`: plain, stripes, checks, grain, or books on shelves `period_m` apart, in
    `pattern_color` with period `period_m`)."""

    color: tuple[float, float, float]
    pattern: int = PATTERN_PLAIN
    pattern_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    period_m: float = 0.1


def yaw_frame(yaw_rad: float) -> FloatArray:
    """(3, 3) rotation whose columns are the local x, y, z axes turned by `yaw_rad` about z."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def axis_frame(axis: FloatArray) -> FloatArray:
    """(3, 3) rotation whose third column is the unit vector `axis` (3,)."""
    z = axis / max(float(np.linalg.norm(axis)), 1e-12)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


@dataclass
class Primitive:
    """Base: a centre (3,), a local frame (3, 3) and a bounding radius (m) around the centre."""

    center: FloatArray
    frame: FloatArray
    radius_m: float
    material: Material
    part: int = 0  # index of the body part or object piece (used for per-part shading tweaks)

    def intersect(self, origins: FloatArray, directions: FloatArray) -> tuple[FloatArray, FloatArray]:
        raise NotImplementedError

    def local_points(self, points: FloatArray) -> FloatArray:
        """(N, 3) world points -> (N, 3) in the primitive's local frame (metres)."""
        return (points - self.center) @ self.frame


@dataclass
class Box(Primitive):
    """Oriented box with half extents `half_m` (3,) along the local axes."""

    half_m: FloatArray = field(default_factory=lambda: np.ones(3))

    def intersect(self, origins: FloatArray, directions: FloatArray) -> tuple[FloatArray, FloatArray]:
        o = (origins - self.center) @ self.frame
        d = directions @ self.frame
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d
            t1 = (-self.half_m - o) * inv
            t2 = (self.half_m - o) * inv
        near = np.fmin(t1, t2)
        far = np.fmax(t1, t2)
        t_near = near.max(axis=1)
        t_far = far.min(axis=1)
        inside = t_near < T_MIN
        t = np.where(inside, t_far, t_near)
        hit = (t_far >= t_near) & (t > T_MIN)
        normal = np.zeros((len(t), 3))
        idx = np.flatnonzero(hit)
        if idx.size:
            axis = np.where(inside[idx], far[idx].argmin(axis=1), near[idx].argmax(axis=1))
            sign = -np.sign(d[idx, axis]) * np.where(inside[idx], -1.0, 1.0)
            local_n = np.zeros((idx.size, 3))
            local_n[np.arange(idx.size), axis] = sign
            normal[idx] = local_n @ self.frame.T
        return np.where(hit, t, np.inf), normal


@dataclass
class Ellipsoid(Primitive):
    """Ellipsoid with semi-axes `radii_m` (3,) along the local axes."""

    radii_m: FloatArray = field(default_factory=lambda: np.ones(3))

    def intersect(self, origins: FloatArray, directions: FloatArray) -> tuple[FloatArray, FloatArray]:
        o = ((origins - self.center) @ self.frame) / self.radii_m
        d = (directions @ self.frame) / self.radii_m
        a = np.einsum("ij,ij->i", d, d)
        o_b = np.broadcast_to(o, d.shape)
        b = np.einsum("ij,ij->i", o_b, d)
        c = np.einsum("ij,ij->i", o_b, o_b) - 1.0
        disc = b * b - a * c
        root = np.sqrt(np.maximum(disc, 0.0))
        t = (-b - root) / a
        t = np.where(t > T_MIN, t, (-b + root) / a)
        hit = (disc >= 0) & (t > T_MIN)
        p = o_b + t[:, None] * d
        normal = (p / self.radii_m) @ self.frame.T
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        return np.where(hit, t, np.inf), normal


@dataclass
class Capsule(Primitive):
    """Capsule: the points within `thickness_m` of the segment `a`-`b` (3,) each."""

    a: FloatArray = field(default_factory=lambda: np.zeros(3))
    b: FloatArray = field(default_factory=lambda: np.ones(3))
    thickness_m: float = 0.05

    def intersect(self, origins: FloatArray, directions: FloatArray) -> tuple[FloatArray, FloatArray]:
        r = self.thickness_m
        ba = self.b - self.a
        oa = np.broadcast_to(origins - self.a, directions.shape)
        baba = float(ba @ ba)
        bard = directions @ ba
        baoa = oa @ ba
        rdoa = np.einsum("ij,ij->i", directions, oa)
        oaoa = np.einsum("ij,ij->i", oa, oa)
        qa = baba - bard * bard
        qb = baba * rdoa - baoa * bard
        qc = baba * oaoa - baoa * baoa - r * r * baba
        h = qb * qb - qa * qc
        with np.errstate(divide="ignore", invalid="ignore"):
            t_body = (-qb - np.sqrt(np.maximum(h, 0.0))) / qa
        y = baoa + t_body * bard
        body = (h >= 0) & (qa > 1e-12) & (y > 0) & (y < baba) & (t_body > T_MIN)
        # Otherwise the ray may hit one of the end spheres.
        cap_origin = np.where((y <= 0)[:, None], oa, oa - ba)
        cb = np.einsum("ij,ij->i", directions, cap_origin)
        cc = np.einsum("ij,ij->i", cap_origin, cap_origin) - r * r
        ch = cb * cb - cc
        t_cap = -cb - np.sqrt(np.maximum(ch, 0.0))
        cap = ~body & (ch > 0) & (t_cap > T_MIN)
        t = np.where(body, t_body, np.where(cap, t_cap, np.inf))
        t_safe = np.where(np.isfinite(t), t, 0.0)
        p = oa + t_safe[:, None] * directions
        along = np.clip((p @ ba) / baba, 0.0, 1.0)
        normal = (p - along[:, None] * ba) / r
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        return t, normal


@dataclass
class Cylinder(Primitive):
    """Capped cylinder of radius `thickness_m` between the points `a` and `b` (3,)."""

    a: FloatArray = field(default_factory=lambda: np.zeros(3))
    b: FloatArray = field(default_factory=lambda: np.ones(3))
    thickness_m: float = 0.05

    def intersect(self, origins: FloatArray, directions: FloatArray) -> tuple[FloatArray, FloatArray]:
        r = self.thickness_m
        ba = self.b - self.a
        oc = np.broadcast_to(origins - self.a, directions.shape)
        baba = float(ba @ ba)
        bard = directions @ ba
        baoc = oc @ ba
        k2 = baba - bard * bard
        k1 = baba * np.einsum("ij,ij->i", oc, directions) - baoc * bard
        k0 = baba * np.einsum("ij,ij->i", oc, oc) - baoc * baoc - r * r * baba
        h = k1 * k1 - k2 * k0
        root = np.sqrt(np.maximum(h, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            t_side = (-k1 - root) / k2
            y = baoc + t_side * bard
            side = (h >= 0) & (np.abs(k2) > 1e-12) & (y > 0) & (y < baba) & (t_side > T_MIN)
            t_cap = (np.where(y < 0, 0.0, baba) - baoc) / bard
            # A ray along the axis meets the nearer cap when it passes within the radius.
            parallel = np.abs(k2) <= 1e-12
            t_near_cap = np.minimum(-baoc / bard, (baba - baoc) / bard)
        t_cap = np.where(parallel, t_near_cap, t_cap)
        cap_hit = np.where(parallel, k0 < 0, np.abs(k1 + k2 * t_cap) < root)
        cap = ~side & (h >= 0) & cap_hit & (t_cap > T_MIN)
        t = np.where(side, t_side, np.where(cap, t_cap, np.inf))
        t_safe = np.where(np.isfinite(t), t, 0.0)
        p = oc + t_safe[:, None] * directions
        side_n = (p - ((p @ ba) / baba)[:, None] * ba) / r
        # The cap's outward normal points away from the cylinder's middle.
        cap_n = np.sign((p @ ba) - baba / 2)[:, None] * ba / np.sqrt(baba)
        normal = np.where(side[:, None], side_n, cap_n)
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        return t, normal


def make_box(center: FloatArray, half_m: FloatArray, yaw_rad: float, material: Material,
             part: int = 0) -> Box:
    return Box(np.asarray(center, float), yaw_frame(yaw_rad), float(np.linalg.norm(half_m)),
               material, part, half_m=np.asarray(half_m, float))


def make_ellipsoid(center: FloatArray, radii_m: FloatArray, frame: FloatArray, material: Material,
                   part: int = 0) -> Ellipsoid:
    return Ellipsoid(np.asarray(center, float), frame, float(np.max(radii_m)), material, part,
                     radii_m=np.asarray(radii_m, float))


def make_capsule(a: FloatArray, b: FloatArray, thickness_m: float, material: Material,
                 part: int = 0) -> Capsule:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return Capsule((a + b) / 2, axis_frame(b - a), float(np.linalg.norm(b - a)) / 2 + thickness_m,
                   material, part, a=a, b=b, thickness_m=thickness_m)


def make_cylinder(a: FloatArray, b: FloatArray, thickness_m: float, material: Material,
                  part: int = 0) -> Cylinder:
    a, b = np.asarray(a, float), np.asarray(b, float)
    half = float(np.linalg.norm(b - a)) / 2
    return Cylinder((a + b) / 2, axis_frame(b - a), float(np.hypot(half, thickness_m)), material,
                    part, a=a, b=b, thickness_m=thickness_m)
