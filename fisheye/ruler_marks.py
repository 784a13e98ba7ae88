"""Ruler marks for lens calibration: pixels of floor points at known distances from the nadir.

The protocol (LOAF paper): a ruler lies on the floor with one end straight below the lens; the user
marks the pixel of that end (the nadir, distance 0) and of marks at known distances, for one or
more rulers laid in several directions. A mark may also carry its floor position (x, y) in the
camera's floor frame (x towards image right, y towards image top, origin at the nadir) when the
ruler's direction is known.

marks.csv (comma-separated, a header row, `#` starts a comment line):

    ruler,u,v,distance_m,x_m,y_m
    east,1476,1476,0,,
    east,1712,1476,1.0,,
    east,1901,1475,2.0,2.0,0.0

`u`, `v` (px) are required; each row needs `distance_m` (m) or both `x_m`, `y_m`; `ruler` is an
optional label. Rows with distance 0 mark the nadir.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fisheye.camera import FisheyeCamera
from fisheye.camera_file import CalibrationError

FloatArray = NDArray[np.float64]

MARK_COLUMNS = ("ruler", "u", "v", "distance_m", "x_m", "y_m")
# |(x, y)| and distance_m of one mark may disagree by this much (a tape reading, not a typo).
_DISTANCE_AGREEMENT_M = 0.01
_DISTANCE_AGREEMENT_RELATIVE = 0.01


def _invalid(message: str) -> CalibrationError:
    return CalibrationError(message, code="invalid_marks")


@dataclass(frozen=True)
class RulerMarks:
    """N marks: `uv_px` (N, 2) px, `distance_m` (N,) m from the nadir, `xy_m` (N, 2) m floor
    positions (NaN rows where only the distance is known) and `ruler` (N,) labels."""

    uv_px: FloatArray
    distance_m: FloatArray
    xy_m: FloatArray
    ruler: tuple[str, ...]

    def __post_init__(self) -> None:
        n = len(self.distance_m)
        if self.uv_px.shape != (n, 2) or self.xy_m.shape != (n, 2) or len(self.ruler) != n:
            raise _invalid(
                f"marks disagree in length: uv_px {self.uv_px.shape}, distance_m {self.distance_m.shape}, "
                f"xy_m {self.xy_m.shape}, ruler {len(self.ruler)}"
            )
        for i in range(n):
            where = f"mark {i + 1} (ruler {self.ruler[i]!r})"
            if not np.isfinite(self.uv_px[i]).all():
                raise _invalid(f"{where}: u, v must be finite pixel coordinates")
            if not (math.isfinite(self.distance_m[i]) and self.distance_m[i] >= 0):
                raise _invalid(f"{where}: distance_m must be a finite number ≥ 0, "
                                       f"got {self.distance_m[i]}")
            has_xy = np.isfinite(self.xy_m[i])
            if has_xy.any() and not has_xy.all():
                raise _invalid(f"{where}: give both x_m and y_m or neither")
            if has_xy.all():
                norm = float(np.hypot(*self.xy_m[i]))
                allowed = max(_DISTANCE_AGREEMENT_M, _DISTANCE_AGREEMENT_RELATIVE * norm)
                if abs(norm - self.distance_m[i]) > allowed:
                    raise _invalid(
                        f"{where}: |(x_m, y_m)| = {norm:.3f} m disagrees with distance_m = "
                        f"{self.distance_m[i]:.3f} m"
                    )

    @classmethod
    def from_arrays(
        cls,
        uv_px: ArrayLike,
        distance_m: ArrayLike | None = None,
        xy_m: ArrayLike | None = None,
        ruler: list[str] | tuple[str, ...] | None = None,
    ) -> RulerMarks:
        """Marks from arrays; `distance_m` defaults to |xy_m|, `xy_m` to unknown (NaN)."""
        uv = np.array(uv_px, dtype=np.float64).reshape(-1, 2)
        n = len(uv)
        xy = np.full((n, 2), np.nan) if xy_m is None else np.array(xy_m, dtype=np.float64).reshape(-1, 2)
        if distance_m is None:
            if xy_m is None:
                raise _invalid("marks need distance_m or xy_m")
            distance = np.hypot(xy[:, 0], xy[:, 1])
        else:
            distance = np.array(distance_m, dtype=np.float64).reshape(-1)
        labels = tuple(str(r) for r in ruler) if ruler is not None else ("",) * n
        return cls(uv, distance, xy, labels)

    def __len__(self) -> int:
        return len(self.distance_m)

    @property
    def is_nadir(self) -> NDArray[np.bool_]:
        """(N,) True for the marks of the nadir (distance 0)."""
        return np.asarray(self.distance_m == 0)

    @property
    def has_xy(self) -> NDArray[np.bool_]:
        """(N,) True for the marks whose floor position (x, y) is known."""
        return np.asarray(np.isfinite(self.xy_m).all(axis=1))


def _number(row: dict[str, str], column: str, line: int, source: str) -> float:
    text = (row.get(column) or "").strip()
    if not text:
        return math.nan
    try:
        value = float(text)
    except ValueError:
        raise _invalid(f"{source} line {line}: {column} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise _invalid(f"{source} line {line}: {column} must be finite, got {text!r}")
    return value


def parse_marks_csv(text: str, source: str = "marks.csv") -> RulerMarks:
    """RulerMarks from the text of a marks.csv (format in the module docstring)."""
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines())
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise _invalid(f"{source} is empty")
    reader = csv.DictReader(io.StringIO("\n".join(line for _, line in lines)), skipinitialspace=True)
    header = [name.strip() for name in reader.fieldnames or []]
    reader.fieldnames = header
    unknown = [name for name in header if name not in MARK_COLUMNS]
    if unknown:
        raise _invalid(f"{source}: unknown column(s) {unknown}; columns are {list(MARK_COLUMNS)}")
    for required in ("u", "v"):
        if required not in header:
            raise _invalid(f"{source}: column {required!r} is missing")
    if "distance_m" not in header and not {"x_m", "y_m"} <= set(header):
        raise _invalid(f"{source}: needs a distance_m column or x_m and y_m columns")
    uv, distance, xy, labels = [], [], [], []
    for (line, _), row in zip(lines[1:], reader, strict=True):
        if None in row:
            raise _invalid(f"{source} line {line}: more fields than the header names")
        u, v = _number(row, "u", line, source), _number(row, "v", line, source)
        if math.isnan(u) or math.isnan(v):
            raise _invalid(f"{source} line {line}: u and v are required")
        point = (_number(row, "x_m", line, source), _number(row, "y_m", line, source))
        d = _number(row, "distance_m", line, source)
        if math.isnan(d):
            if math.isnan(point[0]) or math.isnan(point[1]):
                raise _invalid(f"{source} line {line}: give distance_m or both x_m and y_m")
            d = math.hypot(*point)
        if d < 0:
            raise _invalid(f"{source} line {line}: distance_m must be ≥ 0, got {d}")
        uv.append((u, v))
        distance.append(d)
        xy.append(point)
        labels.append((row.get("ruler") or "").strip())
    if not uv:
        raise _invalid(f"{source} has a header but no marks")
    try:
        return RulerMarks(np.array(uv), np.array(distance), np.array(xy), tuple(labels))
    except CalibrationError as error:
        raise _invalid(f"{source}: {error}") from None


def read_marks_csv(path: str | Path) -> RulerMarks:
    """RulerMarks from a marks.csv file."""
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8")
    except OSError as error:
        raise _invalid(f"cannot read marks file {file}: {error.strerror}") from None
    return parse_marks_csv(text, source=str(file))


def simulate_ruler_marks(
    camera: FisheyeCamera,
    directions_deg: ArrayLike,
    distances_m: ArrayLike,
    noise_px: float = 0.0,
    seed: int | None = None,
    with_xy: bool = False,
) -> RulerMarks:
    """The marks a user would take of `camera`: one ruler per floor-frame direction (degrees,
    counter-clockwise from x), a mark at each distance (> 0) plus one nadir mark, every pixel
    displaced by Gaussian noise of `noise_px` per axis. For planning a calibration and for tests."""
    rng = np.random.default_rng(seed)
    distances = np.asarray(distances_m, dtype=np.float64).reshape(-1)
    uv = [camera.floor_to_pixels(np.zeros((1, 2)))]  # the principal point, unless the camera is tilted
    distance, xy, labels = [np.zeros(1)], [np.zeros((1, 2))], ["nadir"]
    for direction in np.asarray(directions_deg, dtype=np.float64).reshape(-1):
        unit = np.array([math.cos(math.radians(direction)), math.sin(math.radians(direction))])
        points = distances[:, None] * unit
        uv.append(camera.floor_to_pixels(points))
        distance.append(distances)
        xy.append(points)
        labels += [f"{direction:g}deg"] * len(distances)
    pixels = np.concatenate(uv)
    pixels = pixels + rng.normal(0.0, noise_px, pixels.shape) if noise_px > 0 else pixels
    floor = np.concatenate(xy) if with_xy else None
    return RulerMarks.from_arrays(pixels, np.concatenate(distance), floor, labels)


def marks_to_csv(marks: RulerMarks) -> str:
    """The marks.csv text of some marks (floor positions written where known)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(MARK_COLUMNS)
    for i in range(len(marks)):
        x, y = marks.xy_m[i]
        writer.writerow([
            marks.ruler[i], repr(float(marks.uv_px[i, 0])), repr(float(marks.uv_px[i, 1])),
            repr(float(marks.distance_m[i])),
            "" if math.isnan(x) else repr(float(x)), "" if math.isnan(y) else repr(float(y)),
        ])
    return out.getvalue()
