"""Overload and soak: `fishloc serve` in a child process under a fixed-duration mixed load on
loopback, with its resident memory sampled from /proc/PID/status.

    python tests/reliability/reliability_soak.py --seconds 1800          # the long run (docs/RELIABILITY.md)
    python tests/reliability/reliability_soak.py --seconds 20 --json out.json

Clients (threads with keep-alive connections) loop until the duration passes or each has sent
`--max-requests`, mixing good frames, bad frames, camera replacements and reads. The admission
limit is kept low so that the server is overloaded on purpose: those frames must get 503 with
Retry-After. The run passes when every request got an answer, no answer was a 5xx other than
such a 503, and the memory of the late window is not above the early one by more than the margin.
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import sys
import tempfile
import threading
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

if __name__ == "__main__":  # run as a script: this checkout's packages first, then the test helpers
    sys.path[:0] = [str(Path(__file__).resolve().parents[2]), str(Path(__file__).resolve().parent)]

import httpx
from reliability_samples import Samples
from reliability_support import ServeProcess, save_double_model, serve_args, vm_rss_kib

from fisheye import camera_to_dict, load_camera
from models import DEMO_CAMERA_PATH


@dataclass(frozen=True)
class SoakConfig:
    seconds: float = 20.0
    clients: int = 6
    max_requests: int = 100_000        # per client: the loop is bounded in count as well as time
    max_in_flight: int = 2             # low on purpose: overload must answer 503 + Retry-After
    threads: int = 1
    rss_margin: float = 0.10           # the late window may exceed the early one by 10 % ...
    rss_slack_kib: int = 24 * 1024     # ... plus 24 MiB (allocator noise, caches filling)
    model: Path | None = None          # default: the plumbing test double
    seed: int = 0


@dataclass
class SoakReport:
    requests: int = 0
    unanswered: int = 0
    statuses: dict[str, int] = field(default_factory=dict)
    bad_answers: list[str] = field(default_factory=list)
    rss_samples_kib: list[int] = field(default_factory=list)
    rss_early_kib: float = 0.0
    rss_late_kib: float = 0.0
    latency_p50_ms: float = 0.0
    latency_p95_ms: float = 0.0
    seconds: float = 0.0

    def passed(self, config: SoakConfig) -> bool:
        flat = self.rss_late_kib <= self.rss_early_kib * (1 + config.rss_margin) + config.rss_slack_kib
        return self.requests > 0 and self.unanswered == 0 and not self.bad_answers and flat


def _windows(samples: list[int]) -> tuple[float, float]:
    """Median RSS of the early window (the second fifth of the run, after warm-up and the first
    requests) and of the late window (the last fifth)."""
    fifth = max(len(samples) // 5, 1)
    early = samples[fifth:2 * fifth] or samples[:1]
    late = samples[-fifth:]
    return float(statistics.median(early)), float(statistics.median(late))


def run_soak(config: SoakConfig, work_dir: Path) -> SoakReport:
    camera = load_camera(DEMO_CAMERA_PATH)
    samples = Samples(camera)
    frames = [samples.good_jpeg, samples.png_gray, samples.jpeg_cmyk]
    bad = [samples.random_bytes, samples.jpeg_truncated, samples.black_jpeg(640, 480), b""]
    record = camera_to_dict(camera) | {"id": "soak"}
    model = config.model or save_double_model(work_dir / "double.onnx")
    args = serve_args(model, work_dir / "soak.db", "--threads", str(config.threads))
    env = {"FISHLOC_MAX_IN_FLIGHT": str(config.max_in_flight)}
    report = SoakReport()
    lock = threading.Lock()
    statuses: Counter[str] = Counter()
    latencies: list[float] = []
    server = ServeProcess(args, env, keep_lines=2000).start()
    try:
        server.wait_ready()
        assert httpx.put(f"{server.url}/v1/cameras/soak", json=record).status_code in (200, 201)
        start = time.monotonic()
        deadline = start + config.seconds
        stop_sampling = threading.Event()

        def sample_memory() -> None:
            while not stop_sampling.wait(0.25):
                report.rss_samples_kib.append(vm_rss_kib(server.pid))

        def client(index: int) -> None:
            rng = random.Random(config.seed * 1000 + index)
            with httpx.Client(base_url=server.url, timeout=60) as http:
                for _ in range(config.max_requests):
                    if time.monotonic() >= deadline:
                        return
                    roll = rng.random()
                    began = time.perf_counter()
                    try:
                        if roll < 0.70:
                            answer = http.post("/v1/cameras/soak/detect", content=rng.choice(frames),
                                               headers={"content-type": "image/jpeg"})
                            expected = {200, 503}
                        elif roll < 0.85:
                            answer = http.post("/v1/cameras/soak/detect", content=rng.choice(bad),
                                               headers={"content-type": "image/jpeg"})
                            expected = {400, 415, 422, 503}
                        elif roll < 0.92:
                            altitude = round(rng.uniform(2.5, 4.0), 3)
                            answer = http.put("/v1/cameras/soak", json=record | {"altitude_m": altitude})
                            expected = {200}
                        elif roll < 0.97:
                            answer = http.get("/v1/cameras")
                            expected = {200}
                        else:
                            answer = http.get("/metrics")
                            expected = {200}
                    except httpx.HTTPError as error:
                        with lock:
                            report.requests += 1
                            report.unanswered += 1
                            report.bad_answers.append(f"no answer: {error!r}")
                        continue
                    elapsed_ms = (time.perf_counter() - began) * 1e3
                    problem = None
                    if answer.status_code not in expected:
                        request = answer.request
                        problem = f"{request.method} {request.url.path}: {answer.status_code} "
                        problem += answer.text[:200]
                    elif answer.status_code == 503 and not answer.headers.get("retry-after"):
                        problem = "503 without Retry-After"
                    with lock:
                        report.requests += 1
                        statuses[str(answer.status_code)] += 1
                        latencies.append(elapsed_ms)
                        if problem:
                            report.bad_answers.append(problem)

        sampler = threading.Thread(target=sample_memory, daemon=True)
        sampler.start()
        clients = [threading.Thread(target=client, args=(i,)) for i in range(config.clients)]
        for thread in clients:
            thread.start()
        for thread in clients:
            thread.join(config.seconds + 120)
        stop_sampling.set()
        sampler.join(5)
        report.seconds = time.monotonic() - start
        if any(thread.is_alive() for thread in clients):
            report.bad_answers.append("a client did not finish")
        assert httpx.get(f"{server.url}/readyz").status_code == 200
    finally:
        server.stop()
    report.statuses = dict(sorted(statuses.items()))
    report.rss_early_kib, report.rss_late_kib = _windows(report.rss_samples_kib)
    if latencies:
        ordered = sorted(latencies)
        report.latency_p50_ms = ordered[len(ordered) // 2]
        report.latency_p95_ms = ordered[int(len(ordered) * 0.95)]
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--minutes", type=float, help="instead of --seconds")
    parser.add_argument("--clients", type=int, default=6)
    parser.add_argument("--max-in-flight", type=int, default=2)
    parser.add_argument("--model", type=Path, help="ONNX model (default: the plumbing test double)")
    parser.add_argument("--json", type=Path, help="write the report here")
    args = parser.parse_args(argv)
    seconds = args.minutes * 60 if args.minutes else args.seconds
    config = SoakConfig(seconds=seconds, clients=args.clients, max_in_flight=args.max_in_flight,
                        model=args.model)
    with tempfile.TemporaryDirectory(prefix="fishloc-soak-") as folder:
        report = run_soak(config, Path(folder))
    summary = asdict(report) | {"passed": report.passed(config)}
    summary["rss_samples_kib"] = len(report.rss_samples_kib)
    summary["bad_answers"] = report.bad_answers[:20]
    text = json.dumps(summary, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")
    return 0 if report.passed(config) else 1


if __name__ == "__main__":
    sys.exit(main())
