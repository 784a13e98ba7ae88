"""Check a FishLoc replica container behind a sites bus from outside: a `fishloc sites` container
tracks what it publishes, so a frame of a site's camera comes back with track ids and the site's
occupancy holds its people.

Usage: python deploy/ci/bus_smoke_client.py --http http://127.0.0.1:PORT [--samples samples]
Exit 0 when every check passed; prints one line per check.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from smoke_client import SmokeError, http, wait_ready

SITE = "smoke-hall"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--http", required=True)
    parser.add_argument("--samples", type=Path, default=Path("samples"))
    parser.add_argument("--timeout-s", type=float, default=180.0)
    args = parser.parse_args()
    base = args.http.rstrip("/")
    try:
        wait_ready(base, args.timeout_s)
        status, body = http("GET", f"{base}/readyz")
        ready = json.loads(body)
        if ready.get("sites_bus") != "ok":
            raise SmokeError(f"/readyz says the sites bus is {ready.get('sites_bus')!r}")
        status, body = http("GET", f"{base}/v1/cameras/demo")
        camera = {**json.loads(body), "site": SITE, "site_pose": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0}}
        status, body = http("PUT", f"{base}/v1/cameras/demo", json.dumps(camera).encode(), "application/json")
        if status not in (200, 201):
            raise SmokeError(f"camera PUT: HTTP {status} {body[:200]!r}")
        frame = sorted(args.samples.glob("*.jpg"))[0].read_bytes()
        answers = []
        for step in range(3):  # a track is confirmed at its second capture time
            status, body = http("POST", f"{base}/v1/cameras/demo/detect?capture_time={1.8e9 + step * 0.2!r}",
                                frame, "image/jpeg", timeout_s=60)
            if status != 200:
                raise SmokeError(f"detect: HTTP {status} {body[:200]!r}")
            answers.append(json.loads(body))
        last = answers[-1]
        if "site_note" in last or not any(d["track_id"] for d in last["detections"]):
            raise SmokeError(f"the sites worker did not track the frame: {last.get('site_note')!r}")
        print(f"bus smoke: detect answered with track ids ({len(last['detections'])} detections)")
        status, body = http("GET", f"{base}/v1/sites/{SITE}/occupancy")
        occupancy = json.loads(body)
        if status != 200 or occupancy["count"] < 1 or occupancy["time"] != 1.8e9 + 0.4:
            raise SmokeError(f"occupancy: HTTP {status} {body[:300]!r}")
        print(f"bus smoke: occupancy of {SITE}: {occupancy['count']} people at the last frame")
    except (SmokeError, OSError, ValueError, KeyError) as error:
        print(f"bus smoke: FAILED: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
