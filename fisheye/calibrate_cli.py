"""`fishloc calibrate`: fit a camera file from ruler marks, or import an OpenCV fisheye calibration.

    fishloc calibrate --marks marks.csv --altitude 3.2 --image-size 2952 2952 -o camera.yaml
    fishloc calibrate --opencv K_D.yaml --altitude 3.2 -o camera.yaml
    fishloc calibrate --check-altitude camera.yaml --marks marks.csv
    fishloc calibrate --image-circle frame.jpg [--altitude 3] -o camera.yaml

The marks.csv format is described in fisheye/ruler_marks.py and the README ("Calibration").
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path

import numpy as np

from fisheye.altitude_check import check_altitude
from fisheye.calibration import MAX_COEFFICIENTS, RulerFit, RulerFitConfig, fit_ruler_calibration
from fisheye.camera import CAMERA_ID_PATTERN, FisheyeCamera
from fisheye.camera_file import (
    ASSUMED_ALTITUDE_M,
    CalibrationError,
    camera_from_opencv,
    load_camera,
    read_opencv_calibration,
    save_camera,
)
from fisheye.image_circle import camera_from_circle, fit_image_circle, starting_camera_notes
from fisheye.ruler_marks import read_marks_csv

_DEFAULT_ID = "camera"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--marks", type=Path, metavar="CSV",
                        help="ruler marks: columns ruler,u,v,distance_m[,x_m,y_m] (distance 0 = nadir)")
    source.add_argument("--opencv", type=Path, metavar="FILE",
                        help="OpenCV fisheye calibration (FileStorage YAML/JSON, or YAML/JSON with K, D)")
    source.add_argument("--image-circle", type=Path, metavar="FRAME",
                        help="a frame (JPEG/PNG) of the camera: fit its image circle and write a starting "
                             "camera, an equidistant 180° lens whose 90° ring is the circle (--altitude "
                             f"defaults to {ASSUMED_ALTITUDE_M:g} m)")
    parser.add_argument("--altitude", type=float, metavar="M",
                        help="lens height above the floor (m); required unless --check-altitude")
    parser.add_argument("--image-size", type=int, nargs=2, metavar=("W", "H"),
                        help="resolution of the frame the marks were taken on (px); for --opencv, the "
                             "frame size if the file has none (or a size to scale it to)")
    parser.add_argument("-o", "--output", type=Path, metavar="FILE",
                        help="camera file to write (.yaml, .yml or .json); required unless --check-altitude")
    parser.add_argument("--check-altitude", type=Path, metavar="CAMERA",
                        help="with --marks at known floor distances (or x, y): fit the altitude that best "
                             "explains them with this camera file's lens and report it beside the "
                             "configured one (writes nothing)")
    parser.add_argument("--id", dest="camera_id", metavar="ID",
                        help="camera id (default: the output file's name without suffix)")
    parser.add_argument("--coefficients", type=int, default=3, metavar="N",
                        help=f"number of kb coefficients to fit, 1..{MAX_COEFFICIENTS} (default 3)")
    focal = parser.add_mutually_exclusive_group()
    focal.add_argument("--fit-focal", action="store_true",
                       help="fit fx with k1 = 1 (the default when --focal is not given)")
    focal.add_argument("--focal", type=float, metavar="F",
                       help="keep this fx (px) and fit k1 with the other coefficients")
    parser.add_argument("--aspect", type=float, default=1.0, metavar="A", help="fy/fx (default 1)")
    parser.add_argument("--fit-aspect", action="store_true", help="fit fy/fx as well")
    parser.add_argument("--principal-point", type=float, nargs=2, metavar=("U", "V"),
                        help="principal point (px; default: the nadir mark)")
    parser.add_argument("--fit-principal-point", action="store_true",
                        help="refine the principal point from all marks (needs rulers in 2+ directions)")
    parser.add_argument("--fit-tilt", action="store_true",
                        help="fit the camera's tilt from straight down (needs rulers in 3+ directions; "
                             "fits the principal point too unless --principal-point is given)")
    parser.add_argument("--max-theta-deg", type=float, metavar="DEG",
                        help="calibrated field: rays beyond this angle from the axis get no position")


def _default_id(output: Path) -> str:
    stem = output.stem
    return stem if re.match(CAMERA_ID_PATTERN, stem) else _DEFAULT_ID


def _format(value: float, spec: str) -> str:
    """`value` formatted by `spec` (which starts with its width), or a right-aligned '-' if NaN."""
    text = format(value, spec)
    return text if math.isfinite(value) else "-".rjust(len(text))


def residual_table(fit: RulerFit) -> str:
    """The per-mark residual table and the summary lines printed by the command."""
    marks, res = fit.marks, fit.residuals
    header = (f"{'mark':>4}  {'ruler':<8} {'u':>9} {'v':>9} {'dist_m':>8} {'fitted_m':>9} "
              f"{'err_m':>8} {'pos_err_m':>9} {'err_px':>7}")
    lines = [header]
    for i in range(len(marks)):
        lines.append(
            f"{i + 1:>4}  {marks.ruler[i][:8]:<8} {marks.uv_px[i, 0]:>9.1f} {marks.uv_px[i, 1]:>9.1f} "
            f"{marks.distance_m[i]:>8.3f} {_format(res.fitted_distance_m[i], '9.3f')} "
            f"{_format(res.distance_error_m[i], '+8.3f')} {_format(res.position_error_m[i], '9.3f')} "
            f"{_format(res.pixel_error_px[i], '7.2f')}"
        )
    worst = int(np.nanargmax(np.abs(res.distance_error_m)))
    lines.append(
        f"RMS {fit.rms_m:.4f} m, {fit.rms_px:.2f} px over {len(marks)} marks; largest error "
        f"{fit.max_abs_m:.4f} m (mark {worst + 1})"
    )
    return "\n".join(lines)


def describe_camera(camera: FisheyeCamera) -> str:
    kb = ", ".join(f"{k:.6g}" for k in camera.kb)
    return (
        f"camera {camera.id}: {camera.image_size[0]}x{camera.image_size[1]} px, altitude "
        f"{camera.altitude_m:g} m, principal point ({camera.principal_point[0]:.2f}, "
        f"{camera.principal_point[1]:.2f}), focal ({camera.focal_px[0]:.2f}, {camera.focal_px[1]:.2f}) px, "
        f"kb [{kb}], field {camera.theta_max_deg:g}°"
        + ("" if camera.is_level or camera.tilt_deg is None else
           f", tilt [{camera.tilt_deg[0]:.3f}°, {camera.tilt_deg[1]:.3f}°]")
    )


def _from_marks(args: argparse.Namespace, camera_id: str) -> FisheyeCamera:
    if args.image_size is None:
        raise CalibrationError("--image-size W H is required with --marks")
    config = RulerFitConfig(
        coefficients=args.coefficients,
        focal_px=args.focal,
        aspect_ratio=args.aspect,
        fit_aspect_ratio=args.fit_aspect,
        principal_point=tuple(args.principal_point) if args.principal_point else None,
        fit_principal_point=args.fit_principal_point,
        max_theta_deg=args.max_theta_deg,
        fit_tilt=args.fit_tilt,
    )
    marks = read_marks_csv(args.marks)
    fit = fit_ruler_calibration(marks, args.altitude, tuple(args.image_size), camera_id, config)
    print(residual_table(fit))
    for note in fit.notes:
        print(f"{'warning' if note.level == 'warning' else 'note'}: {note}")
    return fit.camera


def _from_opencv(args: argparse.Namespace, camera_id: str) -> FisheyeCamera:
    K, D, stored_size = read_opencv_calibration(args.opencv)
    requested = tuple(args.image_size) if args.image_size is not None else None
    size = stored_size or requested
    if size is None:
        raise CalibrationError(f"{args.opencv} has no image size; give --image-size W H")
    extra = {} if args.max_theta_deg is None else {"max_theta_deg": args.max_theta_deg}
    camera = camera_from_opencv(camera_id, K, D, size, args.altitude, **extra)
    if requested is not None and requested != size:
        try:
            camera = camera.scaled_to(requested)
        except ValueError as error:
            raise CalibrationError(f"image_size: {error}") from None
    return camera


def _from_image_circle(args: argparse.Namespace, camera_id: str) -> FisheyeCamera:
    import cv2

    bgr = cv2.imread(str(args.image_circle), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    if bgr is None:
        raise CalibrationError(f"cannot read {args.image_circle} as an image (JPEG or PNG)")
    circle = fit_image_circle(np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8))
    camera = camera_from_circle(circle, camera_id, args.altitude)
    if args.image_size is not None and tuple(args.image_size) != camera.image_size:
        try:
            camera = camera.scaled_to(tuple(args.image_size))
        except ValueError as error:
            raise CalibrationError(f"image_size: {error}") from None
    print(f"image circle: {int(circle.inliers.sum())} of {len(circle.inliers)} rim points on the circle, "
          f"RMS {circle.rms_px:.2f} px")
    for note in starting_camera_notes(circle, camera):
        print(f"{'warning' if note.level == 'warning' else 'note'}: {note}")
    return camera


def _check_altitude(args: argparse.Namespace) -> int:
    try:
        if args.marks is None:
            raise CalibrationError("--check-altitude needs --marks (marks at known floor distances)")
        camera = load_camera(args.check_altitude)
        if args.image_size is not None and tuple(args.image_size) != camera.image_size:
            camera = camera.scaled_to(tuple(args.image_size))
        check = check_altitude(camera, read_marks_csv(args.marks))
    except (CalibrationError, OSError, ValueError) as error:
        print(f"fishloc calibrate: error: {error}", file=sys.stderr)
        return 2
    print(check.report())
    return 0


def run(args: argparse.Namespace) -> int:
    if args.check_altitude is not None:
        return _check_altitude(args)
    if args.image_circle is not None and args.altitude is None:
        args.altitude = ASSUMED_ALTITUDE_M
    if args.altitude is None or args.output is None:
        print("fishloc calibrate: error: --altitude and -o/--output are required to fit or import a "
              "camera", file=sys.stderr)
        return 2
    camera_id = args.camera_id or _default_id(args.output)
    try:
        if args.marks:
            camera = _from_marks(args, camera_id)
        elif args.image_circle is not None:
            camera = _from_image_circle(args, camera_id)
        else:
            camera = _from_opencv(args, camera_id)
        save_camera(camera, args.output)
    except (CalibrationError, OSError) as error:
        print(f"fishloc calibrate: error: {error}", file=sys.stderr)
        return 2
    print(describe_camera(camera))
    print(f"wrote {args.output}")
    return 0
