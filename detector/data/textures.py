"""Procedural surface textures (tiles, carpet, wood, asphalt, paving, grass, concrete) and their
filtered sampling.

A texture is an image in surface coordinates (metres / `texel_m`) with a mip pyramid; a lookup
picks the pyramid level from each pixel's footprint on the surface, so the far floor near the rim
of the image circle is smooth instead of aliased.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
Image32 = NDArray[np.float32]

FLOOR_KINDS = ("tiles", "carpet", "wood", "asphalt", "paving", "grass", "concrete")
_DETAIL_SIZE = 512
_REMAP_WIDTH = 4096  # cv2.remap wants maps narrower than 32767 px; rows of this width are used


def tileable_noise(rng: np.random.Generator, size: int, cells: tuple[int, int]) -> Image32:
    """(size, size) float32 value noise in [0, 1] that wraps at its borders; `cells` (x, y) sets
    the number of noise cells across."""
    grid = rng.random((cells[1], cells[0])).astype(np.float32)
    tiled = np.tile(grid, (3, 3))
    big = cv2.resize(tiled, (3 * size, 3 * size), interpolation=cv2.INTER_CUBIC)
    return np.clip(big[size:2 * size, size:2 * size], 0.0, 1.0)


def fractal_noise(rng: np.random.Generator, size: int, base_cells: int, octaves: int = 4) -> Image32:
    """Sum of `octaves` tileable noises, each twice as fine and half as strong; float32 in ~[0, 1]."""
    total = np.zeros((size, size), np.float32)
    weight_sum = 0.0
    for octave in range(octaves):
        cells = min(base_cells * 2 ** octave, size)
        weight = 0.5 ** octave
        total += weight * tileable_noise(rng, size, (cells, cells))
        weight_sum += weight
    return total / weight_sum


def _half(image: Image32) -> Image32:
    """Half-size (area average) image of any channel count (cv2.resize takes at most 4)."""
    h, w = image.shape[:2]
    size = (max(w // 2, 1), max(h // 2, 1))
    parts = [cv2.resize(np.ascontiguousarray(image[..., c:c + 4]), size, interpolation=cv2.INTER_AREA)
             for c in range(0, image.shape[2], 4)]
    parts = [p if p.ndim == 3 else p[..., None] for p in parts]
    return np.concatenate(parts, axis=2)


@dataclass(frozen=True)
class Texture:
    """An RGB float32 texture pyramid (level 0 first) in surface metres: texel `texel_m`, origin
    `origin_m` (the corner of texel 0), repeated when `wrap` (else the border colour repeats)."""

    levels: tuple[Image32, ...]
    texel_m: float
    origin_m: tuple[float, float] = (0.0, 0.0)
    wrap: bool = True

    @classmethod
    def build(cls, image: Image32, texel_m: float, origin_m: tuple[float, float] = (0.0, 0.0),
              wrap: bool = True) -> Texture:
        levels = [np.ascontiguousarray(image, dtype=np.float32)]
        while min(levels[-1].shape[:2]) > 2 and len(levels) < 10:
            levels.append(_half(levels[-1]))
        return cls(tuple(levels), texel_m, origin_m, wrap)

    def sample(self, x_m: FloatArray, y_m: FloatArray, footprint_m: FloatArray) -> Image32:
        """(N,) surface coordinates and pixel footprints (m) -> (N, C) float32 texel values."""
        n = len(x_m)
        channels = self.levels[0].shape[2]
        out = np.zeros((n, channels), np.float32)
        if n == 0:
            return out
        lod = np.log2(np.maximum(footprint_m / self.texel_m, 1.0))
        lod = np.clip(lod, 0.0, len(self.levels) - 1.0)
        low = np.minimum(np.floor(lod).astype(np.int64), len(self.levels) - 2)
        frac = (lod - low).astype(np.float32)
        u = (x_m - self.origin_m[0]) / self.texel_m
        v = (y_m - self.origin_m[1]) / self.texel_m
        if self.wrap:
            h0, w0 = self.levels[0].shape[:2]
            u = np.mod(u, w0)
            v = np.mod(v, h0)
        for level in np.unique(np.concatenate([low, low + 1])):
            weight = np.where(low == level, 1.0 - frac, 0.0) + np.where(low + 1 == level, frac, 0.0)
            take = np.flatnonzero(weight > 0)
            if take.size == 0:
                continue
            scale = 2.0 ** level
            colors = self._remap(int(level), u[take] / scale - 0.5, v[take] / scale - 0.5)
            out[take] += weight[take, None] * colors
        return out

    def _remap(self, level: int, u: FloatArray, v: FloatArray) -> Image32:
        n = len(u)
        rows = -(-n // _REMAP_WIDTH)
        pad = rows * _REMAP_WIDTH - n
        map_u = np.concatenate([u, np.zeros(pad)]).astype(np.float32).reshape(rows, _REMAP_WIDTH)
        map_v = np.concatenate([v, np.zeros(pad)]).astype(np.float32).reshape(rows, _REMAP_WIDTH)
        border = cv2.BORDER_WRAP if self.wrap else cv2.BORDER_REPLICATE
        sampled = cv2.remap(self.levels[level], map_u, map_v, cv2.INTER_LINEAR, borderMode=border)
        return np.asarray(sampled, np.float32).reshape(n + pad, -1)[:n]


def wrap_blur(image: Image32, sigma: float) -> Image32:
    """Gaussian blur of a tileable image that keeps it tileable (OpenCV has no wrapping blur)."""
    pad = max(1, int(3 * sigma + 1))
    widths = ((pad, pad), (pad, pad)) + ((0, 0),) * (image.ndim - 2)
    blurred = cv2.GaussianBlur(np.pad(image, widths, mode="wrap"), (0, 0), sigma)
    return np.asarray(blurred[pad:-pad, pad:-pad], np.float32)


def _jitter(rng: np.random.Generator, color: FloatArray, amount: float) -> FloatArray:
    return np.clip(color * (1.0 + amount * rng.normal(size=3)), 0.0, 1.0)


def _speckle(rng: np.random.Generator, size: int, strength: float) -> Image32:
    """Per-texel grain around 1 (fine random noise, softened a little)."""
    grain = rng.normal(0.0, 1.0, (size, size)).astype(np.float32)
    grain = wrap_blur(grain, 0.7)
    return 1.0 + strength * grain / max(float(grain.std()), 1e-6)


def floor_texture(kind: str, colors: FloatArray, rng: np.random.Generator, scale_m: float) -> Texture:
    """A tileable floor texture of `kind` (one of FLOOR_KINDS) in the palette `colors` (K, 3) linear
    RGB; `scale_m` is its characteristic size (tile, plank width, stone length)."""
    size = _DETAIL_SIZE
    base = colors[0].astype(np.float32)
    second = colors[1 % len(colors)].astype(np.float32)
    image = np.empty((size, size, 3), np.float32)
    image[:] = base
    yy, xx = np.mgrid[0:size, 0:size]
    if kind == "tiles":
        per = 4
        texel = per * scale_m / size
        cell = size // per
        ix, iy = xx // cell, yy // cell
        shades = 1.0 + 0.06 * rng.normal(size=(per, per)).astype(np.float32)
        image *= shades[iy, ix][..., None]
        if rng.random() < 0.35:  # two-colour checkerboard
            image[(ix + iy) % 2 == 1] = second * shades[iy, ix][(ix + iy) % 2 == 1][:, None]
        image *= (0.9 + 0.2 * fractal_noise(rng, size, 4, 3))[..., None]
        image *= _speckle(rng, size, 0.03)[..., None]
        grout = max(1, round(0.005 / texel))
        joint = ((xx % cell) < grout) | ((yy % cell) < grout)
        image[joint] = colors[2 % len(colors)] * 0.8
    elif kind == "carpet":
        texel = 2.0 / size
        image *= (0.85 + 0.3 * fractal_noise(rng, size, 8, 4))[..., None]
        image *= _speckle(rng, size, 0.12)[..., None]
        dots = rng.random((size, size)) < 0.04
        image[dots] = image[dots] * 0.6 + 0.4 * second
        if rng.random() < 0.5:  # carpet tiles laid in alternating directions
            cell = max(8, round(scale_m / texel))
            checker = ((xx // cell) + (yy // cell)) % 2 == 1
            image[checker] *= 0.93
    elif kind == "wood":
        planks = 8
        texel = planks * scale_m / size
        cell = size // planks
        row = yy // cell
        offsets = rng.integers(0, size, planks)
        lengths = rng.integers(size // 3, size, planks)
        seg = ((xx + offsets[row]) // lengths[row]).astype(np.int64)
        shade = 1.0 + 0.12 * rng.normal(size=(planks, 8)).astype(np.float32)
        image = np.where(rng.random() < 0.5, base, second) * np.ones((size, size, 3), np.float32)
        image *= shade[row, seg % 8][..., None]
        grain = tileable_noise(rng, size, (4, 96)) * 0.6 + tileable_noise(rng, size, (8, 192)) * 0.4
        image *= (0.8 + 0.35 * grain)[..., None]
        gap = ((yy % cell) < 2) | (((xx + offsets[row]) % lengths[row]) < 2)
        image[gap] *= 0.55
    elif kind == "asphalt":
        texel = 2.0 / size
        image *= (0.8 + 0.4 * fractal_noise(rng, size, 4, 4))[..., None]
        image *= _speckle(rng, size, 0.25)[..., None]
        stones = rng.random((size, size)) < 0.02
        image[stones] *= 1.6
    elif kind == "paving":
        per = 8
        texel = per * scale_m / size
        cell = size // per
        row = yy // (cell // 2)
        shift = (row % 2) * (cell // 2)
        ix = (xx + shift) // cell
        shades = 1.0 + 0.1 * rng.normal(size=(2 * per, per + 1)).astype(np.float32)
        image *= shades[row, ix][..., None]
        pick = rng.random((2 * per, per + 1)) < 0.3
        image[pick[row, ix]] = (second * shades[row, ix][pick[row, ix]][:, None])
        image *= (0.85 + 0.3 * fractal_noise(rng, size, 8, 3))[..., None]
        image *= _speckle(rng, size, 0.08)[..., None]
        joint = ((yy % (cell // 2)) < 2) | (((xx + shift) % cell) < 2)
        image[joint] *= 0.6
    elif kind == "grass":
        texel = 2.0 / size
        blades = wrap_blur(rng.normal(0, 1, (size, size)).astype(np.float32), 0.8)
        mix = fractal_noise(rng, size, 4, 4)
        image = base * (1 - mix[..., None]) + second * mix[..., None]
        image *= (1.0 + 0.25 * blades / max(float(blades.std()), 1e-6))[..., None]
        image *= (0.8 + 0.4 * fractal_noise(rng, size, 2, 2))[..., None]
    elif kind == "concrete":
        texel = 2 * scale_m / size
        image *= (0.85 + 0.3 * fractal_noise(rng, size, 6, 5))[..., None]
        image *= _speckle(rng, size, 0.05)[..., None]
        joint = ((xx % (size // 2)) < 2) | ((yy % (size // 2)) < 2)
        image[joint] *= 0.7
    else:
        raise ValueError(f"unknown floor kind {kind!r}; choose from {', '.join(FLOOR_KINDS)}")
    return Texture.build(np.clip(image, 0.0, 1.0), texel)
