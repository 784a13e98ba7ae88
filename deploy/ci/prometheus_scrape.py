"""Scrape a running FishLoc with a real Prometheus, using the compose file's Prometheus config.

Usage: python deploy/ci/prometheus_scrape.py --target 127.0.0.1:PORT [--prometheus /usr/bin/prometheus]

The `fishloc` job of deploy/prometheus/prometheus.yml (metrics path, job name) is kept; only its
target (the compose service name) is replaced by --target and the interval shortened. Passes when
Prometheus reports the target up and holds the service's frame counter. Exit 0 on success.
"""

from __future__ import annotations

import argparse
import json
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from pathlib import Path
from typing import Any

import yaml

CONFIG = Path(__file__).resolve().parents[1] / "prometheus" / "prometheus.yml"


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def scrape_config(target: str) -> dict[str, Any]:
    """The committed config with the fishloc job pointed at `target`, scraped every second."""
    config = yaml.safe_load(CONFIG.read_text(encoding="utf-8"))
    jobs = [job for job in config["scrape_configs"] if job["job_name"] == "fishloc"]
    if len(jobs) != 1:
        raise SystemExit(f"{CONFIG} has no single `fishloc` job")
    config["scrape_configs"] = jobs  # the compose file's other targets do not exist here
    jobs[0]["static_configs"] = [{"targets": [target]}]
    jobs[0]["scrape_interval"] = "1s"
    config["global"]["scrape_interval"] = "1s"
    return dict(config)


def query(api: str, expression: str) -> float | None:
    """The value of an instant query with one result, or None."""
    url = f"{api}/api/v1/query?" + urllib.parse.urlencode({"query": expression})
    with urllib.request.urlopen(url, timeout=5) as response:
        answer = json.load(response)
    results = answer.get("data", {}).get("result", [])
    return float(results[0]["value"][1]) if len(results) == 1 else None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", required=True, help="host:port of the FishLoc REST API")
    parser.add_argument("--prometheus", default=shutil.which("prometheus") or "prometheus")
    parser.add_argument("--timeout-s", type=float, default=60.0)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="fishloc-prometheus-") as folder:
        config_path = Path(folder) / "prometheus.yml"
        config_path.write_text(yaml.safe_dump(scrape_config(args.target)), encoding="utf-8")
        port = _free_port()
        api = f"http://127.0.0.1:{port}"
        with (Path(folder) / "log").open("wb") as log:
            process = subprocess.Popen(
                [args.prometheus, f"--config.file={config_path}", f"--storage.tsdb.path={folder}/data",
                 f"--web.listen-address=127.0.0.1:{port}"],
                stdout=log, stderr=subprocess.STDOUT,
            )
        try:
            deadline = time.monotonic() + args.timeout_s
            up = frames = None
            while time.monotonic() < deadline:
                try:
                    up = query(api, 'up{job="fishloc"}')
                    frames = query(api, 'sum(fishloc_frames_total{job="fishloc"})')
                except OSError:
                    pass
                if up == 1 and frames is not None and frames >= 1:
                    print(f"prometheus: job fishloc up, fishloc_frames_total = {frames:g}")
                    return 0
                if process.poll() is not None:
                    break
                time.sleep(1)
            log_text = (Path(folder) / "log").read_text(errors="replace")[-2000:]
            print(f"prometheus: FAILED: up={up}, frames={frames}\n{log_text}", file=sys.stderr)
            return 1
        finally:
            process.terminate()
            process.wait(timeout=30)


if __name__ == "__main__":
    sys.exit(main())
