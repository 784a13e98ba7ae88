"""Colour pools for scenes and people, split into disjoint seen/unseen halves.

Each material kind has a fixed pool of preset colours (made from a fixed seed, so the pools are the
same on every machine); a preset belongs to the seen split or to the unseen split, never both, so
the floors, walls and furniture of unseen scenes never appear in seen ones. Clothing and skin are
drawn from continuous ranges shared by both splits (people are not what a split is about).
"""

from __future__ import annotations

import colorsys

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

SPLITS = ("seen", "unseen")
_POOL_SIZE = 24
_UNSEEN_EVERY = 3  # presets with index % 3 == 2 are unseen, the rest seen

# kind -> (hue range, saturation range, value range) in HSV of sRGB
_RANGES: dict[str, tuple[tuple[float, float], tuple[float, float], tuple[float, float]]] = {
    "tiles": ((0.0, 1.0), (0.0, 0.25), (0.45, 0.92)),
    "carpet": ((0.0, 1.0), (0.03, 0.3), (0.2, 0.6)),
    "wood": ((0.05, 0.1), (0.35, 0.7), (0.3, 0.75)),
    "asphalt": ((0.55, 0.65), (0.0, 0.08), (0.18, 0.42)),
    "paving": ((0.0, 0.12), (0.0, 0.35), (0.4, 0.8)),
    "grass": ((0.18, 0.3), (0.35, 0.7), (0.25, 0.55)),
    "concrete": ((0.0, 0.15), (0.0, 0.1), (0.5, 0.8)),
    "wall": ((0.0, 1.0), (0.0, 0.22), (0.62, 0.95)),
    "facade": ((0.0, 0.15), (0.05, 0.45), (0.35, 0.85)),
    "furniture": ((0.0, 1.0), (0.05, 0.6), (0.15, 0.8)),
    "rug": ((0.0, 1.0), (0.2, 0.7), (0.2, 0.7)),
    "car": ((0.0, 1.0), (0.0, 0.8), (0.1, 0.9)),
    "foliage": ((0.2, 0.36), (0.35, 0.75), (0.15, 0.45)),
}


def srgb_to_linear(rgb: FloatArray) -> FloatArray:
    rgb = np.asarray(rgb, dtype=np.float64)
    return np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)


def _pool(kind: str) -> FloatArray:
    hue, sat, val = _RANGES[kind]
    rng = np.random.default_rng([sum(map(ord, kind)), 4242])
    out = []
    for _ in range(_POOL_SIZE):
        h = rng.uniform(*hue) % 1.0
        s = rng.uniform(*sat)
        v = rng.uniform(*val)
        out.append(colorsys.hsv_to_rgb(h, s, v))
    return srgb_to_linear(np.array(out))


_POOLS = {kind: _pool(kind) for kind in _RANGES}


def preset_indices(split: str) -> NDArray[np.int64]:
    """The preset indices (into every pool) that belong to `split`."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    all_idx = np.arange(_POOL_SIZE)
    unseen = all_idx % _UNSEEN_EVERY == _UNSEEN_EVERY - 1
    return all_idx[unseen] if split == "unseen" else all_idx[~unseen]


def scene_color(kind: str, split: str, rng: np.random.Generator, jitter: float = 0.04) -> FloatArray:
    """A linear-RGB (3,) colour of material `kind` from the presets of `split`, slightly varied."""
    index = int(rng.choice(preset_indices(split)))
    base = _POOLS[kind][index]
    return np.clip(base * (1.0 + jitter * rng.normal(size=3)), 0.0, 1.0)


def scene_palette(kind: str, split: str, rng: np.random.Generator, count: int = 3) -> FloatArray:
    """(count, 3) colours of one material: a preset and darker/lighter relatives of it."""
    first = scene_color(kind, split, rng)
    rows = [first]
    for _ in range(count - 1):
        rows.append(np.clip(first * rng.uniform(0.6, 1.3) + rng.normal(0, 0.02, 3), 0.0, 1.0))
    return np.array(rows)


def clothing_color(rng: np.random.Generator) -> FloatArray:
    """A linear-RGB clothing colour: many dark/neutral garments, some saturated ones."""
    r = rng.random()
    if r < 0.35:
        v = rng.uniform(0.05, 0.35)
        rgb = colorsys.hsv_to_rgb(rng.uniform(0, 1), rng.uniform(0, 0.25), v)
    elif r < 0.55:
        rgb = colorsys.hsv_to_rgb(rng.uniform(0, 1), rng.uniform(0, 0.1), rng.uniform(0.6, 0.95))
    elif r < 0.7:
        rgb = colorsys.hsv_to_rgb(rng.uniform(0.55, 0.67), rng.uniform(0.3, 0.8), rng.uniform(0.2, 0.7))
    else:
        rgb = colorsys.hsv_to_rgb(rng.uniform(0, 1), rng.uniform(0.35, 0.9), rng.uniform(0.3, 0.9))
    return srgb_to_linear(np.array(rgb))


def skin_color(rng: np.random.Generator) -> FloatArray:
    """A linear-RGB skin tone from very light to very dark."""
    tone = rng.uniform(0.0, 1.0)
    light = np.array([0.96, 0.80, 0.69])
    dark = np.array([0.30, 0.19, 0.13])
    rgb = light * (1 - tone) + dark * tone
    return srgb_to_linear(np.clip(rgb * (1 + 0.04 * rng.normal(size=3)), 0, 1))


def hair_color(rng: np.random.Generator) -> FloatArray:
    """A linear-RGB hair colour: mostly black and brown, some blond, grey and dyed."""
    r = rng.random()
    if r < 0.5:
        rgb = np.array([0.06, 0.05, 0.045]) * rng.uniform(0.7, 1.6)
    elif r < 0.8:
        rgb = np.array([0.30, 0.20, 0.12]) * rng.uniform(0.5, 1.3)
    elif r < 0.9:
        rgb = np.array([0.75, 0.62, 0.40]) * rng.uniform(0.8, 1.1)
    elif r < 0.97:
        rgb = np.full(3, rng.uniform(0.5, 0.85))
    else:
        rgb = np.array(colorsys.hsv_to_rgb(rng.uniform(0, 1), 0.6, 0.6))
    return srgb_to_linear(np.clip(rgb, 0, 1))
