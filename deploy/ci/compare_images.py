"""Two FishLoc images side by side: each runs as a container (2 CPUs, read-only root), the same
frame is POSTed to each in turn, and the medians of the answers' stage times are compared.

    python deploy/ci/compare_images.py OLD_IMAGE NEW_IMAGE FRAME.jpg [--runs 30] [--camera demo]

Taking turns frame by frame puts both images under the same load, so the ratio holds on a busy
machine where the milliseconds do not. Needs a running Docker engine.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import statistics
import subprocess
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

DOCKER = "/usr/bin/docker"
WARM_UP = 3


@contextlib.contextmanager
def container(image: str, name: str) -> Iterator[str]:
    """`image` running as `name`; yields its REST base URL once /readyz answers."""
    subprocess.run([DOCKER, "rm", "-f", name], capture_output=True, check=False)
    subprocess.run([DOCKER, "run", "-d", "--name", name, "--cpus", "2", "--read-only", "--tmpfs", "/tmp",
                    "-p", "127.0.0.1::8000", image], check=True, capture_output=True)
    try:
        port = subprocess.run([DOCKER, "port", name, "8000/tcp"], capture_output=True, text=True,
                              check=True).stdout.splitlines()[0].rsplit(":", 1)[1]
        url = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 120
        while True:
            try:
                urllib.request.urlopen(f"{url}/readyz", timeout=2)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"{image} did not become ready") from None
                time.sleep(0.2)
        yield url
    finally:
        subprocess.run([DOCKER, "rm", "-f", name], capture_output=True, check=False)


def detect(url: str, camera: str, frame: bytes) -> dict[str, float]:
    """One frame's stage times (ms), with the whole HTTP round trip as `http`."""
    request = urllib.request.Request(f"{url}/v1/cameras/{camera}/detect", data=frame,
                                     headers={"Content-Type": "image/jpeg"})
    start = time.perf_counter()
    with urllib.request.urlopen(request, timeout=60) as response:
        answer = json.load(response)
    return {**answer["timing_ms"], "http": (time.perf_counter() - start) * 1e3}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old")
    parser.add_argument("new")
    parser.add_argument("frame")
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--camera", default="demo")
    args = parser.parse_args()
    frame = Path(args.frame).read_bytes()
    images = [args.old, args.new]
    times: dict[str, dict[str, list[float]]] = {image: {} for image in images}
    with container(args.old, "fishloc-compare-old") as old_url, \
            container(args.new, "fishloc-compare-new") as new_url:
        for run in range(WARM_UP + args.runs):
            for image, url in zip(images, (old_url, new_url), strict=True):
                for stage, value in detect(url, args.camera, frame).items():
                    if run >= WARM_UP:
                        times[image].setdefault(stage, []).append(value)
    print(f"{args.runs} frames each, taking turns; medians in ms")
    print(f"{'stage':<12} {args.old:>20} {args.new:>20}  ratio")
    for stage in times[args.old]:
        old, new = statistics.median(times[args.old][stage]), statistics.median(times[args.new][stage])
        print(f"{stage:<12} {old:>20.1f} {new:>20.1f}  {new / old:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
