"""Scene-sized canvases drawn in metres: the floor overlay (markings, rugs, kerbs, second material,
large-scale dirt and light variation) and the unrolled walls (paint, doors, windows, boards, façades).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from detector.data.textures import Texture, fractal_noise

FloatArray = NDArray[np.float64]
Image32 = NDArray[np.float32]

_MAX_SIDE = 2048


class Canvas:
    """A float32 image over the metre rectangle `extent` (x0, y0, x1, y1); row = (y - y0) / texel."""

    def __init__(self, extent: tuple[float, float, float, float], texel_m: float, channels: int,
                 fill: FloatArray) -> None:
        x0, y0, x1, y1 = extent
        self.texel_m = max(texel_m, (x1 - x0) / _MAX_SIDE, (y1 - y0) / _MAX_SIDE)
        self.origin = (x0, y0)
        width = max(2, int(np.ceil((x1 - x0) / self.texel_m)))
        height = max(2, int(np.ceil((y1 - y0) / self.texel_m)))
        self.image = np.empty((height, width, channels), np.float32)
        self.image[:] = np.asarray(fill, np.float32)

    def _px(self, x: float, y: float) -> tuple[int, int]:
        return (round((x - self.origin[0]) / self.texel_m), round((y - self.origin[1]) / self.texel_m))

    def rect(self, x0: float, y0: float, x1: float, y1: float, value: FloatArray,
             channels: slice = slice(None)) -> None:
        """Fill the axis-aligned metre rectangle with `value` in `channels`."""
        c0, r0 = self._px(min(x0, x1), min(y0, y1))
        c1, r1 = self._px(max(x0, x1), max(y0, y1))
        h, w = self.image.shape[:2]
        c0, c1, r0, r1 = max(c0, 0), min(max(c1, c0 + 1), w), max(r0, 0), min(max(r1, r0 + 1), h)
        if c0 < c1 and r0 < r1:
            self.image[r0:r1, c0:c1, channels] = np.asarray(value, np.float32)

    def polygon(self, points_m: FloatArray, value: FloatArray) -> None:
        """Fill a polygon given in metres (K, 2) with `value` (all channels)."""
        pts = ((np.asarray(points_m) - np.array(self.origin)) / self.texel_m * 16).round().astype(np.int32)
        mask = np.zeros(self.image.shape[:2], np.uint8)
        cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_AA, shift=4)
        self.image[mask > 0] = np.asarray(value, np.float32)

    def multiply_noise(self, rng: np.random.Generator, amount: float, cells: int, channels: slice) -> None:
        """Multiply `channels` by large-scale noise around 1 (dirt, wear, uneven light)."""
        h, w = self.image.shape[:2]
        side = 256
        noise = fractal_noise(rng, side, cells, 4)
        noise = np.asarray(cv2.resize(noise, (w, h), interpolation=cv2.INTER_LINEAR), np.float32)
        self.image[..., channels] *= (1.0 + amount * (noise - 0.5) * 2)[..., None]

    def multiply_light(self, lamps: FloatArray, sigma_m: float) -> None:
        """Brighten `channels` 0-2 in pools round the lamps (K, 3: x, y, strength) above."""
        h, w = self.image.shape[:2]
        cell = max(self.texel_m, 0.1)
        gw, gh = max(2, int(w * self.texel_m / cell)), max(2, int(h * self.texel_m / cell))
        xs = self.origin[0] + (np.arange(gw) + 0.5) * w * self.texel_m / gw
        ys = self.origin[1] + (np.arange(gh) + 0.5) * h * self.texel_m / gh
        gain = np.ones((gh, gw), np.float32)
        for lx, ly, strength in lamps:
            gain += (strength * np.exp(-((ys[:, None] - ly) ** 2 + (xs[None, :] - lx) ** 2)
                                       / (2 * sigma_m ** 2))).astype(np.float32)
        full = cv2.resize(gain, (w, h), interpolation=cv2.INTER_LINEAR)
        self.image[..., :3] *= np.asarray(full, np.float32)[..., None]

    def texture(self) -> Texture:
        return Texture.build(self.image, self.texel_m, self.origin, wrap=False)


def floor_canvas(extent: tuple[float, float, float, float], texel_m: float) -> Canvas:
    """A floor overlay: channels tint/colour RGB (1 = untinted), alpha of painted colour, weight of
    the second floor material."""
    return Canvas(extent, texel_m, 5, np.array([1.0, 1.0, 1.0, 0.0, 0.0]))


def paint_stripe(canvas: Canvas, a: FloatArray, b: FloatArray, width_m: float, color: FloatArray,
                 alpha: float = 0.9) -> None:
    """A painted line (markings) from a to b (2,) m."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    direction = (b - a) / max(float(np.linalg.norm(b - a)), 1e-9)
    side = np.array([-direction[1], direction[0]]) * width_m / 2
    poly = np.array([a - side, b - side, b + side, a + side])
    canvas.polygon(poly, np.array([*color, alpha, 0.0]))


class WallPainter:
    """The unrolled walls: s (m) round the enclosure from (x0, y0) counter-clockwise, z (m) up."""

    def __init__(self, room_m: tuple[float, float, float, float], height_m: float, texel_m: float,
                 base: FloatArray) -> None:
        x0, y0, x1, y1 = room_m
        width, depth = x1 - x0, y1 - y0
        self.lengths = (width, depth, width, depth)
        self.starts = (0.0, width, width + depth, 2 * width + depth)
        self.height_m = height_m
        perimeter = 2 * (width + depth)
        self.canvas = Canvas((0.0, 0.0, perimeter, height_m), texel_m, 3, base)

    def walls(self) -> list[tuple[float, float]]:
        """(start s, length) of the four walls."""
        return list(zip(self.starts, self.lengths, strict=True))

    def rect(self, s0: float, z0: float, s1: float, z1: float, color: FloatArray) -> None:
        self.canvas.rect(s0, z0, s1, z1, color)

    def framed(self, s0: float, z0: float, s1: float, z1: float, color: FloatArray, frame: FloatArray,
               border_m: float) -> None:
        self.rect(s0, z0, s1, z1, frame)
        self.rect(s0 + border_m, z0 + border_m, s1 - border_m, z1 - border_m, color)

    def texture(self) -> Texture:
        return self.canvas.texture()


def paint_room_walls(painter: WallPainter, rng: np.random.Generator, paint: FloatArray,
                     accent: FloatArray, wood: FloatArray, classroom: bool) -> None:
    """Room walls: paint (one accent wall sometimes), baseboard, doors, windows, boards, posters."""
    for index, (start, length) in enumerate(painter.walls()):
        color = accent if index == 0 and rng.random() < 0.3 else paint
        painter.rect(start, 0.0, start + length, painter.height_m, color)
        painter.rect(start, 0.0, start + length, rng.uniform(0.06, 0.14), color * rng.uniform(0.3, 0.8))
        used: list[tuple[float, float]] = []

        def free_spot(size: float, _start: float = start, _length: float = length,
                      _used: list[tuple[float, float]] = used) -> float | None:
            for _ in range(8):
                s = rng.uniform(_start + 0.2, _start + _length - size - 0.2) if _length > size + 0.4 else None
                if s is None:
                    return None
                if all(s + size < a or s > b for a, b in _used):
                    _used.append((s, s + size))
                    return s
            return None

        for _ in range(rng.integers(0, 3)):
            door_w = rng.uniform(0.85, 1.7)
            s = free_spot(door_w)
            if s is not None:
                door = wood if rng.random() < 0.6 else paint * rng.uniform(0.5, 0.9)
                painter.framed(s, 0.0, s + door_w, 2.1, door, paint * 0.6, 0.05)
        for _ in range(rng.integers(0, 4)):
            win_w = rng.uniform(1.0, 2.5)
            s = free_spot(win_w)
            if s is not None:
                glass = np.array([0.75, 0.85, 1.0]) * rng.uniform(0.6, 1.0)
                painter.framed(s, 0.9, s + win_w, min(2.5, painter.height_m - 0.1), glass,
                               np.full(3, 0.7), 0.06)
        boards = 1 if classroom else rng.integers(0, 3)
        for _ in range(boards):
            bw = rng.uniform(1.2, 3.5) if classroom else rng.uniform(0.5, 1.6)
            s = free_spot(bw)
            if s is not None:
                white = rng.random() < 0.6
                color = np.full(3, 0.85) if white else rng.uniform(0.1, 0.8, 3)
                painter.framed(s, 0.9, s + bw, 0.9 + min(1.2, bw * 0.7), color, np.full(3, 0.5), 0.03)
        for _ in range(rng.integers(0, 5)):
            s = free_spot(0.1)
            if s is not None:
                z = rng.uniform(0.3, 1.3)
                painter.rect(s, z, s + 0.08, z + 0.12, np.full(3, rng.uniform(0.1, 0.9)))
    # A cornice under the ceiling, and light that fades up the walls away from the lamps' pools.
    painter.rect(0.0, painter.height_m - rng.uniform(0.03, 0.12), 2 * sum(painter.lengths),
                 painter.height_m, paint * rng.uniform(0.85, 1.1))
    painter.canvas.multiply_noise(rng, 0.08, 6, slice(0, 3))
    rows = painter.canvas.image.shape[0]
    height_share = (np.arange(rows) + 0.5) / rows
    fade = 1.0 - rng.uniform(0.05, 0.3) * height_share ** 1.5
    painter.canvas.image *= fade.astype(np.float32)[:, None, None]
    grain = rng.normal(0.0, 1.0, painter.canvas.image.shape[:2]).astype(np.float32)
    painter.canvas.image *= (1.0 + 0.02 * grain)[..., None]


def darken_edges(canvas: Canvas, room_m: tuple[float, float, float, float], width_m: float,
                 amount: float) -> None:
    """Ambient occlusion along the foot of the walls: the floor darkens towards them."""
    h, w = canvas.image.shape[:2]
    xs = canvas.origin[0] + (np.arange(w) + 0.5) * canvas.texel_m
    ys = canvas.origin[1] + (np.arange(h) + 0.5) * canvas.texel_m
    x0, y0, x1, y1 = room_m
    dx = np.minimum(xs - x0, x1 - xs)
    dy = np.minimum(ys - y0, y1 - ys)
    gap = np.minimum(dy[:, None], dx[None, :])
    shade = 1.0 - amount * np.exp(-np.maximum(gap, 0.0) / width_m)
    canvas.image[..., :3] *= shade.astype(np.float32)[..., None]


def paint_facades(painter: WallPainter, rng: np.random.Generator, colors: FloatArray) -> None:
    """Building façades: blocks of colour with rows of windows, shop fronts and doors."""
    for start, length in painter.walls():
        s = start
        while s < start + length:
            width = rng.uniform(6.0, 25.0)
            end = min(s + width, start + length)
            color = colors[rng.integers(len(colors))] * rng.uniform(0.8, 1.2)
            top = painter.height_m * rng.uniform(0.5, 1.0)
            painter.rect(s, 0.0, end, top, color)
            glass = np.array([0.12, 0.15, 0.2]) * rng.uniform(0.5, 2.0)
            storey = rng.uniform(2.8, 3.6)
            pitch = rng.uniform(1.8, 3.5)
            win = pitch * rng.uniform(0.35, 0.7)
            z = storey
            while z + storey * 0.6 < top:
                x = s + 0.5 * (pitch - win)
                while x + win < end:
                    painter.rect(x, z + 0.9, x + win, z + storey * 0.8, glass)
                    x += pitch
                z += storey
            if rng.random() < 0.6:  # shop front
                painter.rect(s + 0.5, 0.3, end - 0.5, 2.6, glass * rng.uniform(1.0, 3.0))
            door_at = rng.uniform(s, max(s, end - 1.5))
            painter.rect(door_at, 0.0, door_at + 1.2, 2.3, color * 0.4)
            s = end
    painter.canvas.multiply_noise(rng, 0.12, 8, slice(0, 3))
