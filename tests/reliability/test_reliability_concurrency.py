"""A camera replaced and deleted while frames for it are in flight: every answer is one that some
registry state explains (200 with the positions of one of the altitudes written, or 404), never a 5xx."""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable

import httpx
import numpy as np
from reliability_samples import PERSON_FLOOR_XY_M, Samples
from reliability_support import LiveServer

from fisheye import FisheyeCamera, camera_to_dict
from service.core.config import Settings

pytest_plugins = ["reliability_fixtures"]

ALTITUDES_M = (2.0, 4.0)
FRAMES_PER_CLIENT = 40
WRITES = 60


def test_put_and_delete_while_frames_are_in_flight(settings_for: Callable[..., Settings],
                                                   demo_camera: FisheyeCamera) -> None:
    samples = Samples(demo_camera)
    record = camera_to_dict(demo_camera) | {"id": "flip"}
    allowed = [np.array(PERSON_FLOOR_XY_M) * altitude / demo_camera.altitude_m for altitude in ALTITUDES_M]
    statuses: Counter[int] = Counter()
    problems: list[str] = []
    lock = threading.Lock()
    with LiveServer(settings_for(threads=2, max_in_flight=4)) as live:
        url = f"{live.url}/v1/cameras/flip"
        assert httpx.put(url, json=record | {"altitude_m": ALTITUDES_M[0]}).status_code == 201
        done = threading.Event()

        def writer() -> None:
            with httpx.Client(timeout=30) as client:
                for i in range(WRITES):
                    if i % 3 == 2:
                        answer = client.delete(url)
                        ok = answer.status_code in (204, 404)
                    else:
                        answer = client.put(url, json=record | {"altitude_m": ALTITUDES_M[i % 2]})
                        ok = answer.status_code in (200, 201)
                    if not ok:
                        with lock:
                            problems.append(f"write {answer.status_code} {answer.text[:200]}")
            done.set()

        def detector() -> None:
            with httpx.Client(timeout=30) as client:
                for _ in range(FRAMES_PER_CLIENT):
                    answer = client.post(f"{url}/detect", content=samples.good_jpeg,
                                         headers={"content-type": "image/jpeg"})
                    with lock:
                        statuses[answer.status_code] += 1
                    if answer.status_code == 200:
                        position = np.array(max(answer.json()["detections"], key=lambda d: d["score"])
                                            ["position_m"])
                        if not any(np.allclose(position, expected, atol=0.02) for expected in allowed):
                            with lock:
                                problems.append(f"position {position} fits no altitude written")
                    elif answer.status_code == 404:
                        assert answer.json()["error"]["code"] == "camera_not_found"
                    elif answer.status_code == 503:
                        assert answer.headers["retry-after"]
                    else:
                        with lock:
                            problems.append(f"detect {answer.status_code} {answer.text[:200]}")

        threads = [threading.Thread(target=writer)] + [threading.Thread(target=detector) for _ in range(3)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(120)
        assert done.is_set() and not any(thread.is_alive() for thread in threads)
        assert httpx.get(f"{live.url}/readyz").status_code == 200
    assert not problems, problems[:5]
    assert sum(statuses.values()) == 3 * FRAMES_PER_CLIENT  # every frame answered
    assert set(statuses) <= {200, 404, 503} and statuses[200] > 0
