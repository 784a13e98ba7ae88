"""What fusion and tracking add to a frame of a site's camera, in one process, on synthetic walkers.

    python -m benchmarks.site_fusion [--people 20] [--cameras 4] [--seconds 60] [--fps 10]
                                     [--late 0.05] [--json OUT]

People walk at 0.5-1.5 m/s, turning now and then, on a floor covered by a row of cameras whose views
overlap; each camera sends a frame of every step with the people it sees (position noise growing
with the distance from its nadir). A share `--late` of the frames arrives after the next step's
frames (within the reordering window, so the site's tracks are replayed). Each frame is timed as the
service runs it: `SiteTracker.update` and the occupancy answer built after it; wall time, and the
thread's own CPU time (which other processes on a busy machine do not inflate).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass

import numpy as np

from benchmarks.stats import summarize
from sites import CountingLine, SiteLayout, SiteObservation, SiteTracker, Zone


@dataclass(frozen=True)
class Scene:
    people: int
    cameras: int
    seconds: float
    fps: float
    seed: int = 0
    view_m: float = 6.0     # each camera sees this far from its nadir
    spacing_m: float = 8.0  # between neighbouring nadirs


def observations(scene: Scene) -> list[SiteObservation]:
    """Every camera's frame of every step, in capture order."""
    rng = np.random.default_rng(scene.seed)
    nadirs = np.array([[scene.spacing_m * k, 0.0] for k in range(scene.cameras)])
    low, high = np.array([-4.0, -5.0]), np.array([scene.spacing_m * (scene.cameras - 1) + 4.0, 5.0])
    where = rng.uniform(low, high, (scene.people, 2))
    heading = rng.uniform(0, 2 * np.pi, scene.people)
    speed = rng.uniform(0.5, 1.5, scene.people)
    frames: list[SiteObservation] = []
    dt = 1.0 / scene.fps
    for step in range(round(scene.seconds * scene.fps)):
        heading += rng.normal(0.0, 0.15, scene.people)
        where += dt * speed[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
        bounced = (where < low) | (where > high)
        heading[bounced.any(axis=1)] += np.pi
        where = np.clip(where, low, high)
        for nadir in nadirs:
            distance = np.hypot(*(where - nadir).T)
            seen = distance <= scene.view_m
            noise = rng.normal(0.0, 1.0, (int(seen.sum()), 2)) * (0.05 + 0.02 * distance[seen])[:, None]
            frames.append(SiteObservation.of(f"cam-{len(frames) % scene.cameras}", 1.7e9 + step * dt,
                                             where[seen] + noise, distance[seen]))
    return frames


def arrival_order(frames: list[SiteObservation], late_share: float, cameras: int, seed: int) -> list[int]:
    """Indices of `frames` in arrival order: a share of them swapped behind the next step's frames."""
    rng = np.random.default_rng(seed + 1)
    order = list(range(len(frames)))
    for index in range(len(order) - cameras):
        if rng.random() < late_share:
            order[index], order[index + cameras] = order[index + cameras], order[index]
    return order


def run(scene: Scene, late_share: float) -> dict[str, object]:
    frames = observations(scene)
    layout = SiteLayout.of(
        [Zone(f"zone-{k}", np.array([[8.0 * k - 2, -2.0], [8.0 * k + 2, -2.0], [8.0 * k + 2, 2.0],
                                     [8.0 * k - 2, 2.0]])) for k in range(scene.cameras)],
        [CountingLine(f"line-{k}", np.array([8.0 * k + 4, -5.0]), np.array([8.0 * k + 4, 5.0]))
         for k in range(scene.cameras - 1)],
    )
    tracker = SiteTracker("bench", layout=layout)
    elapsed_ms, cpu_ms = [], []
    for index in arrival_order(frames, late_share, scene.cameras, scene.seed):
        start, start_cpu = time.perf_counter(), time.thread_time()
        tracker.update(frames[index])
        tracker.occupancy()
        cpu_ms.append((time.thread_time() - start_cpu) * 1e3)
        elapsed_ms.append((time.perf_counter() - start) * 1e3)
    final = tracker.occupancy()
    return {
        "scene": scene.__dict__, "late_share": late_share, "frames": len(frames),
        "detections_per_frame": round(float(np.mean([len(f) for f in frames])), 2),
        "fusion_ms": summarize(elapsed_ms).as_dict(),
        "fusion_cpu_ms": summarize(cpu_ms).as_dict(),  # the thread's own CPU time: robust to a busy machine
        "tracker_frames": tracker.frames.__dict__, "people_now": final["count"],
        "tracks_started": tracker.ended + final["count"],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--people", type=int, default=20)
    parser.add_argument("--cameras", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--fps", type=float, default=10.0)
    parser.add_argument("--late", type=float, default=0.05, help="share of frames arriving late")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None, help="write the report here too")
    args = parser.parse_args(argv)
    report = run(Scene(args.people, args.cameras, args.seconds, args.fps, args.seed), args.late)
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as out:
            out.write(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
