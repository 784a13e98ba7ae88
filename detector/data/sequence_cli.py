"""`fishloc synth --sequence`: render a site's cameras in step while people walk through it."""

from __future__ import annotations

import argparse
import math
import sys
import time

from tqdm import tqdm

from detector.data.sequence import SequenceConfig
from detector.data.sequence_writer import write_sequence
from detector.data.site_world import default_plan, load_plan
from detector.data.synth_writer import ANNOTATIONS_FILE
from fisheye import CalibrationError


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
