"""`fishloc synth`: render a synthetic data set (JPEG frames + annotations.json), or with
`--sequence` a site's cameras capturing in step while people walk through it.

Runs without torch (numpy and OpenCV only), in parallel worker processes; the output depends only
on the seed, split and options, never on the number of workers.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from tqdm import tqdm

from detector.data.contact_sheet import make_contact_sheet
from detector.data.scenes import KINDS, STYLES
from detector.data.sequence import SequenceConfig
from detector.data.sequence_writer import write_sequence
from detector.data.site_world import default_plan, load_plan
from detector.data.synth import BOX_KINDS, SynthConfig
from detector.data.synth_writer import ANNOTATIONS_FILE, default_workers, write_dataset
from fisheye import CalibrationError, load_camera

MAX_SIZE = 2952


def _people(text: str) -> tuple[int, int]:
    try:
        low, _, high = text.partition("-")
        bounds = (int(low), int(high or low))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MIN-MAX people, e.g. 4-12, got {text!r}") from None
    if not 0 <= bounds[0] <= bounds[1] <= 60:
        raise argparse.ArgumentTypeError(f"people must satisfy 0 <= MIN <= MAX <= 60, got {text!r}")
    return bounds


def _styles(text: str) -> str:
    unknown = [s for s in text.split(",") if s not in STYLES]
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown style {unknown[0]!r}; choose from {', '.join(STYLES)}")
    return text


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, type=Path, help="output folder (created)")
    parser.add_argument("--images", type=int, help="number of frames (not with --sequence)")
    parser.add_argument("--size", type=int, default=640, help=f"frame side in px (<= {MAX_SIZE})")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the frames")
    parser.add_argument("--split", choices=("seen", "unseen"), default="seen",
                        help="scene pool: unseen scenes never share layouts or palettes with seen ones")
    parser.add_argument("--camera", type=Path, help="render every frame with this camera file")
    parser.add_argument("--kind", choices=KINDS, help="only indoor or only outdoor scenes")
    parser.add_argument("--style", type=_styles,
                        help=f"only scenes of these styles, comma-separated, in turn ({', '.join(STYLES)})")
    parser.add_argument("--people", type=_people,
                        help="people per frame as MIN-MAX (default 0-60 mix); with --sequence one number: "
                             "people over the whole sequence (default 18 a minute, at least 10)")
    parser.add_argument("--images-per-scene", type=int, default=4, help="frames rendered per scene")
    parser.add_argument("--jpeg-quality", type=int, help="fixed JPEG quality (default: random 70-95)")
    parser.add_argument("--boxes", choices=BOX_KINDS, default="visible",
                        help="each person's box: of the visible silhouette (default) or of the whole "
                             "one, what hides the person ignored, as hand-drawn boxes are (frames only)")
    parser.add_argument("--workers", type=int, default=default_workers(),
                        help="worker processes (default: all cores)")
    sequence = parser.add_argument_group("sequences (--sequence)")
    sequence.add_argument("--sequence", action="store_true",
                          help="render a site's cameras in step: DIR/<camera_id>/*.jpg and tracks")
    sequence.add_argument("--seconds", type=float, default=60.0, help="length of the sequence")
    sequence.add_argument("--fps", type=float, default=5.0, help="steps per second")
    sequence.add_argument("--site", type=Path,
                          help="site file (room, doors, cameras with site_pose, zones, lines); "
                               "default: a built-in hall with two cameras")
    parser.add_argument("--contact-sheet", type=Path, help="also write a PNG grid of the frames")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    if not 16 <= args.size <= MAX_SIZE:
        print(f"fishloc synth: --size must be within [16, {MAX_SIZE}]", file=sys.stderr)
        return 2
    if args.sequence:
        return run_sequence(args)
    if args.images is None:
        print("fishloc synth: --images is required (or --sequence)", file=sys.stderr)
        return 2
    if args.images < 1 or args.images_per_scene < 1:
        print("fishloc synth: --images and --images-per-scene must be positive", file=sys.stderr)
        return 2
    camera = None
    if args.camera is not None:
        try:
            camera = load_camera(args.camera)
        except CalibrationError as error:
            print(f"fishloc synth: {error}", file=sys.stderr)
            return 2
    config = SynthConfig(size=args.size, kind=args.kind, style=args.style, people=args.people, camera=camera,
                         images_per_scene=args.images_per_scene, jpeg_quality=args.jpeg_quality,
                         boxes=args.boxes)
    started = time.perf_counter()
    with tqdm(total=args.images, unit="img", disable=args.quiet) as bar:
        document = write_dataset(args.out, args.images, args.seed, args.split, config,
                                 workers=args.workers, on_frame=lambda: bar.update(1))
    elapsed = time.perf_counter() - started
    people = len(document["annotations"])
    print(f"wrote {args.images} frames, {people} people to {args.out / ANNOTATIONS_FILE} "
          f"in {elapsed:.1f} s ({args.images / elapsed:.2f} img/s, {args.workers} workers)")
    if args.contact_sheet is not None:
        sheet = make_contact_sheet(args.out / ANNOTATIONS_FILE, args.contact_sheet)
        print(f"contact sheet: {sheet}")
    return 0


def run_sequence(args: argparse.Namespace) -> int:
    if args.images is not None:
        print("fishloc synth: --images does not apply to --sequence (use --seconds and --fps)",
              file=sys.stderr)
        return 2
    if not (args.seconds > 0 and args.fps > 0 and math.isfinite(args.seconds * args.fps)):
        print("fishloc synth: --seconds and --fps must be positive", file=sys.stderr)
        return 2
    if args.people is not None and args.people[0] != args.people[1]:
        print("fishloc synth: with --sequence, --people is one number (people over the sequence)",
              file=sys.stderr)
        return 2
    try:
        plan = load_plan(args.site) if args.site is not None else default_plan()
    except (OSError, ValueError, KeyError, TypeError, CalibrationError) as error:
        print(f"fishloc synth: bad site file {args.site}: {error}", file=sys.stderr)
        return 2
    steps = max(1, round(args.seconds * args.fps))
    config = SequenceConfig(plan=plan, steps=steps, fps=args.fps, seed=args.seed, size=args.size,
                            people=None if args.people is None else args.people[0])
    frames = steps * len(plan.cameras)
    started = time.perf_counter()
    with tqdm(total=frames, unit="img", disable=args.quiet) as bar:
        document = write_sequence(args.out, config, workers=args.workers, on_frame=lambda: bar.update(1))
    elapsed = time.perf_counter() - started
    print(f"wrote {steps} steps x {len(plan.cameras)} cameras = {frames} frames, "
          f"{document['info']['people']} people, {len(document['annotations'])} boxes to "
          f"{args.out / ANNOTATIONS_FILE} in {elapsed:.1f} s ({frames / elapsed:.2f} img/s, "
          f"{args.workers} workers)")
    return 0
