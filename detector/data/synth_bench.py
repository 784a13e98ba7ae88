"""Render timing of the synthetic frames, one process: `python -m detector.data.synth_bench`.

Prints wall-clock p50/p95 per frame, the mean CPU time, and the cost of a scene's first frame
(which also builds the scene's rays, textures, surroundings and fixed objects) against the others.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from detector.data.synth import SynthConfig, render_frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--size", type=int, default=640)
    parser.add_argument("--frames", type=int, default=32)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--images-per-scene", type=int, default=4)
    args = parser.parse_args()
    config = SynthConfig(size=args.size, images_per_scene=args.images_per_scene)
    wall, cpu = [], []
    for index in range(args.frames):
        started, cpu_started = time.perf_counter(), time.process_time()
        render_frame(args.seed, "seen", index, config)
        wall.append(time.perf_counter() - started)
        cpu.append(time.process_time() - cpu_started)
    times = np.array(wall)
    first = np.arange(args.frames) % args.images_per_scene == 0
    print(f"size {args.size}, {args.frames} frames: wall p50 {np.percentile(times, 50):.3f} s, "
          f"p95 {np.percentile(times, 95):.3f} s, mean {times.mean():.3f} s; CPU mean {np.mean(cpu):.3f} s")
    if (~first).any():
        rest = times[~first]
        print(f"a scene's first frame: mean {times[first].mean():.3f} s; other frames: "
              f"p50 {np.percentile(rest, 50):.3f} s, p95 {np.percentile(rest, 95):.3f} s")


if __name__ == "__main__":
    main()
