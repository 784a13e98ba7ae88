"""The image-circle fit on real frames, against the circle each frame's camera records.

    python -m benchmarks.image_circle --data ../shared/real-frames/scenes4.json \\
        --data ../shared/real-frames/cepdof_lunch3.json [--renders 40 --size 384] [--json circles.json]

For every frame of each annotation file: the circle `fisheye.image_circle.fit_image_circle` finds
(centre, radius, where the frame cuts it, inlier fraction, RMS) beside the reference circle, the
camera's θmax ring (the file's camera, or for files without one DESIGN.md's assumed camera, whose
circle fills the frame's shorter side), their differences and the fit's time on this machine. A
report, not a test: the reference circles are fitted too, by other means, and are no ground truth.
`--renders N` fits the circles of N frames of the renderer (`fishloc synth`'s, seed 100 on, seen and
unseen scenes, random lenses) too, whose cameras are the truth, and prints the errors' median and
largest.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from detector.data.readers import read_dataset
from fisheye import CalibrationError
from fisheye.image_circle import fit_image_circle


@dataclass(frozen=True)
class CircleRow:
    frame: str
    size_wh: tuple[int, int]
    reference: str  # "file camera" or "assumed"
    reference_center_px: tuple[float, float]
    reference_radius_px: float
    center_px: tuple[float, float] | None = None
    radius_px: float | None = None
    center_error_px: float | None = None
    radius_error_px: float | None = None
    cut: str = ""
    inlier_fraction: float | None = None
    rms_px: float | None = None
    fit_ms: float | None = None
    refused: str = ""


def measure(annotation_file: Path) -> list[CircleRow]:
    rows = []
    for frame in read_dataset(annotation_file):
        camera = frame.camera
        assert camera is not None  # the readers give every frame a camera, assumed where the file has none
        reference = CircleRow(
            frame=frame.path.name, size_wh=(frame.width, frame.height),
            reference="assumed" if frame.camera_assumed else "file camera",
            reference_center_px=camera.principal_point, reference_radius_px=camera.image_circle_radius_px())
        bgr = cv2.imread(str(frame.path), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
        if bgr is None:
            raise SystemExit(f"cannot read {frame.path}")
        rgb = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
        start = time.perf_counter()
        try:
            circle = fit_image_circle(rgb)
        except CalibrationError as error:
            rows.append(CircleRow(**{**asdict(reference), "refused": f"{error.code}: {error}"}))
            continue
        elapsed_ms = 1000 * (time.perf_counter() - start)
        u0, v0 = camera.principal_point
        rows.append(CircleRow(**{
            **asdict(reference),
            "center_px": circle.center_px, "radius_px": circle.radius_px,
            "center_error_px": math.hypot(circle.center_px[0] - u0, circle.center_px[1] - v0),
            "radius_error_px": circle.radius_px - reference.reference_radius_px,
            "cut": "+".join(circle.cut.sides()) or "none", "inlier_fraction": circle.inlier_fraction,
            "rms_px": circle.rms_px, "fit_ms": elapsed_ms,
        }))
    return rows


def table(rows: list[CircleRow]) -> str:
    lines = ["| frame | size | reference | ref. centre, R (px) | fitted centre, R (px) | Δcentre (px) | "
             "ΔR (px) | cut | inliers | RMS (px) | fit (ms) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        ref = (f"({row.reference_center_px[0]:.1f}, {row.reference_center_px[1]:.1f}), "
               f"{row.reference_radius_px:.1f}")
        if row.center_px is None or row.radius_px is None:
            lines.append(f"| {row.frame} | {row.size_wh[0]}x{row.size_wh[1]} | {row.reference} | {ref} | "
                         f"refused: {row.refused} | | | | | | |")
            continue
        lines.append(
            f"| {row.frame} | {row.size_wh[0]}x{row.size_wh[1]} | {row.reference} | {ref} | "
            f"({row.center_px[0]:.1f}, {row.center_px[1]:.1f}), {row.radius_px:.1f} | "
            f"{row.center_error_px:.1f} | {row.radius_error_px:+.1f} | {row.cut} | "
            f"{row.inlier_fraction:.2f} | {row.rms_px:.2f} | {row.fit_ms:.0f} |")
    return "\n".join(lines)


def render_errors(count: int, size: int) -> dict[str, float]:
    """Centre and radius errors (px) of the fit on `count` rendered frames of side `size`."""
    from detector.data.synth import SynthConfig, render_frame

    centre, radius, refused = [], [], 0
    for index in range(count):
        split = "unseen" if index % 2 else "seen"
        frame = render_frame(100 + index, split, index % 4, SynthConfig(size=size))
        bgr = cv2.imdecode(np.frombuffer(frame.jpeg, np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise SystemExit(f"cannot decode rendered frame {index}")
        try:
            circle = fit_image_circle(np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8))
        except CalibrationError:
            refused += 1
            continue
        u0, v0 = frame.camera.principal_point
        centre.append(math.hypot(circle.center_px[0] - u0, circle.center_px[1] - v0))
        radius.append(abs(circle.radius_px - frame.camera.image_circle_radius_px()))
    if not centre:
        return {"frames": count, "refused": refused}
    return {"frames": count, "refused": refused, "centre_median_px": float(np.median(centre)),
            "centre_max_px": float(np.max(centre)), "radius_median_px": float(np.median(radius)),
            "radius_max_px": float(np.max(radius))}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.image_circle", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, action="append", default=[], metavar="ANN.json",
                        help="annotation file (FishLoc or CEPDOF/WEPDTOF format); repeat for several")
    parser.add_argument("--renders", type=int, default=0, metavar="N", help="also fit N rendered frames")
    parser.add_argument("--size", type=int, default=384, metavar="S", help="side of the rendered frames")
    parser.add_argument("--json", type=Path, metavar="OUT.json", help="write the rows as JSON too")
    args = parser.parse_args(argv)
    rows = [row for path in args.data for row in measure(path)]
    print(table(rows))
    renders = render_errors(args.renders, args.size) if args.renders > 0 else None
    if renders is not None:
        print(f"renders ({args.size} px): " + ", ".join(f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}"
                                                       for k, v in renders.items()))
    if args.json is not None:
        report = {"real": [asdict(row) for row in rows], "renders": renders}
        args.json.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
