"""Check a running FishLoc container from outside: ready, a sample frame detected correctly, metrics.

Usage: python deploy/ci/smoke_client.py --http http://127.0.0.1:PORT [--grpc 127.0.0.1:PORT]
           [--samples samples] [--timeout-s 180]

With `samples/annotations.json` present, the frame holding the most people is posted to the `demo`
camera and a third of its people must have a detection within --match-m of their floor position
(0.6 m: the foot point of even a perfect box misses the ankles by 0.2 m at the median); without it,
a grey square JPEG (the demo camera's aspect ratio) checks the answer's shape only, and so does a
model whose metadata says it is untrained (a placeholder cannot find people; this is printed).
Exit 0 when every check passed; prints one line per check.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

DETECTION_FIELDS = ("score", "box", "corners", "foot_px", "position_m", "distance_m", "site_position_m")
BOX_FIELDS = ("cx", "cy", "w", "h", "angle_deg")


class SmokeError(Exception):
    """A check failed."""


def http(method: str, url: str, body: bytes | None = None, content_type: str | None = None,
         timeout_s: float = 30.0) -> tuple[int, bytes]:
    """Status and body of one request (an error status is returned, not raised)."""
    request = urllib.request.Request(url, data=body, method=method)
    if content_type:
        request.add_header("Content-Type", content_type)
    try:
        with urllib.request.urlopen(request, timeout=timeout_s) as response:
            return int(response.status), response.read()
    except urllib.error.HTTPError as error:
        return int(error.code), error.read()


def wait_ready(base: str, timeout_s: float) -> float:
    """Seconds until GET /readyz answered 200."""
    start = time.monotonic()
    last = "no answer"
    while time.monotonic() - start < timeout_s:
        try:
            status, body = http("GET", f"{base}/readyz", timeout_s=5)
            if status == 200:
                return time.monotonic() - start
            last = f"HTTP {status}: {body[:200]!r}"
        except (urllib.error.URLError, OSError) as error:
            last = str(error)
        time.sleep(1)
    raise SmokeError(f"/readyz not ready after {timeout_s:.0f} s (last: {last})")


def pick_frame(samples: Path) -> tuple[bytes, dict[str, Any] | None, list[list[float]]]:
    """A sample frame of the demo camera, its annotation record and its people's floor positions."""
    annotations_path = samples / "annotations.json"
    if not annotations_path.is_file():
        import cv2
        import numpy as np

        print(f"smoke: {annotations_path} missing: posting a grey 1024x1024 JPEG (shape checks only)")
        ok, encoded = cv2.imencode(".jpg", np.full((1024, 1024, 3), 96, np.uint8))
        if not ok:
            raise SmokeError("could not encode the stand-in JPEG")
        return encoded.tobytes(), None, []
    dataset = json.loads(annotations_path.read_text(encoding="utf-8"))
    people: dict[int, list[list[float]]] = {}
    for annotation in dataset["annotations"]:
        if annotation.get("location_m") is not None:
            people.setdefault(int(annotation["image_id"]), []).append(list(annotation["location_m"]))
    images = [image for image in dataset["images"] if (samples / image["file_name"]).is_file()]
    if not images:
        raise SmokeError(f"{annotations_path} names no frame that exists beside it")
    image = max(images, key=lambda record: len(people.get(int(record["id"]), [])))
    return (samples / image["file_name"]).read_bytes(), image, people.get(int(image["id"]), [])


def check_detection_shape(detection: dict[str, Any]) -> None:
    missing = [field for field in DETECTION_FIELDS if field not in detection]
    if missing:
        raise SmokeError(f"detection lacks {missing}: {detection}")
    if not all(field in detection["box"] for field in BOX_FIELDS):
        raise SmokeError(f"box lacks one of {BOX_FIELDS}: {detection['box']}")
    corners = detection["corners"]
    if len(corners) != 4 or any(len(corner) != 2 for corner in corners):
        raise SmokeError(f"corners must be 4 points: {corners}")
    if len(detection["foot_px"]) != 2:
        raise SmokeError(f"foot_px must be 2 numbers: {detection['foot_px']}")
    position = detection["position_m"]
    if position is not None and (len(position) != 2 or not all(math.isfinite(v) for v in position)):
        raise SmokeError(f"position_m must be null or 2 finite numbers: {position}")
    if not 0.0 <= float(detection["score"]) <= 1.0:
        raise SmokeError(f"score outside [0, 1]: {detection['score']}")


def model_is_placeholder(base: str) -> bool:
    """Whether the served model says it is untrained (GET /v1/model `trained_on`), printing it."""
    status, body = http("GET", f"{base}/v1/model")
    if status != 200:
        raise SmokeError(f"/v1/model answered HTTP {status}: {body[:300]!r}")
    model = json.loads(body)
    print(f"smoke: model {model.get('name')} {model.get('version')}, trained on {model.get('trained_on')!r}")
    return "untrained" in str(model.get("trained_on", "")).lower()


def check_detect(base: str, samples: Path, match_m: float) -> None:
    placeholder = model_is_placeholder(base)
    frame, image, truth = pick_frame(samples)
    frame_id = "smoke-1"
    status, body = http("POST", f"{base}/v1/cameras/demo/detect?frame_id={frame_id}", frame, "image/jpeg")
    if status != 200:
        raise SmokeError(f"detect answered HTTP {status}: {body[:500]!r}")
    answer = json.loads(body)
    if answer.get("camera_id") != "demo" or answer.get("frame_id") != frame_id:
        raise SmokeError(f"answer does not echo camera_id/frame_id: {str(answer)[:300]}")
    detections = answer.get("detections")
    if not isinstance(detections, list):
        raise SmokeError(f"detections is not a list: {str(answer)[:300]}")
    for detection in detections:
        check_detection_shape(detection)
    if image is not None:
        size = answer.get("image", {})
        if (size.get("width"), size.get("height")) != (image["width"], image["height"]):
            raise SmokeError(f"image size {size} is not the frame's {image['width']}x{image['height']}")
    print(f"smoke: detect HTTP 200, {len(detections)} detections with every field, "
          f"timing_ms={answer.get('timing_ms')}")
    if image is None:
        return
    if placeholder:
        print("smoke: NOT CHECKED: detection correctness (the served model is an untrained placeholder; "
              "it is checked once a trained default model is shipped)")
        return
    positions = [d["position_m"] for d in detections if d["position_m"] is not None]
    found = [min((math.dist(t, p) for p in positions), default=math.inf) for t in truth]
    matched = sum(error <= match_m for error in found)
    print(f"smoke: {image['file_name']}: {matched}/{len(truth)} people found within {match_m} m")
    # The shipped model places 7 of this frame's 10 people within 0.6 m (tests/service/test_samples.py
    # holds it to 40 % over the three samples); a third is the floor here.
    if truth and matched < len(truth) / 3:
        raise SmokeError(f"only {matched} of the {len(truth)} people have a detection within {match_m} m")


def check_metrics(base: str) -> None:
    status, body = http("GET", f"{base}/metrics")
    text = body.decode("utf-8", "replace")
    if status != 200 or "# TYPE" not in text:
        raise SmokeError(f"/metrics answered HTTP {status} without Prometheus text: {text[:200]!r}")
    print(f"smoke: /metrics HTTP 200, {text.count('# TYPE')} metric families")


def check_grpc_health(target: str, timeout_s: float = 15.0) -> None:
    """grpc.health.v1 Check answers SERVING (what the Kubernetes liveness probe asks)."""
    import grpc
    from grpc_health.v1 import health_pb2, health_pb2_grpc

    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with grpc.insecure_channel(target) as channel:
                stub = health_pb2_grpc.HealthStub(channel)
                reply = stub.Check(health_pb2.HealthCheckRequest(), timeout=5)
            break
        except grpc.RpcError as error:
            if time.monotonic() > deadline:
                raise SmokeError(f"gRPC health on {target}: {error.code()} {error.details()}") from None
            time.sleep(1)
    if reply.status != health_pb2.HealthCheckResponse.SERVING:
        raise SmokeError(f"gRPC health on {target}: status {reply.status}, not SERVING")
    print(f"smoke: gRPC health on {target}: SERVING")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--http", required=True, help="base URL of the REST API")
    parser.add_argument("--grpc", help="host:port of the gRPC server (health check)")
    parser.add_argument("--samples", type=Path, default=Path("samples"))
    parser.add_argument("--timeout-s", type=float, default=180.0)
    parser.add_argument("--match-m", type=float, default=0.6, help="floor distance of a correct detection")
    args = parser.parse_args()
    base = args.http.rstrip("/")
    try:
        print(f"smoke: /readyz 200 after {wait_ready(base, args.timeout_s):.1f} s")
        check_detect(base, args.samples, args.match_m)
        check_metrics(base)
        if args.grpc:
            check_grpc_health(args.grpc)
    except SmokeError as error:
        print(f"smoke: FAILED: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
