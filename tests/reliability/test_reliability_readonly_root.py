"""`fishloc serve` on a read-only root filesystem, as the container runs it (`docker run --read-only`,
Kubernetes `readOnlyRootFilesystem: true`): only the registry's folder is writable (a tmpfs here,
the volume /var/lib/fishloc in the image). It must start, become ready, write cameras and detect.

A machine that does not allow mount namespaces skips it with the reason; in CI (CI=true) that
fails the run, so the read-only root is never left untested there."""

from __future__ import annotations

import subprocess
from pathlib import Path

import httpx
import pytest
from reliability_cases import SCENARIO
from reliability_samples import Samples
from reliability_support import ServeProcess, serve_args

from fisheye import FisheyeCamera, camera_to_dict
from tests.ci_policy import skip_or_fail_in_ci

pytest_plugins = ["reliability_fixtures"]

# In a private mount namespace: root re-mounted read-only, a tmpfs on the registry's folder.
READ_ONLY_ROOT = ["unshare", "--mount", "sh", "-c",
                  'mount --rbind / / && mount -o remount,ro,bind / && mount -t tmpfs tmpfs "$FISHLOC_DATA" '
                  '&& exec "$@"', "sh"]


def _namespaces_allowed(folder: Path) -> bool:
    env = {"FISHLOC_DATA": str(folder), "PATH": "/usr/bin:/bin"}
    try:
        probe = subprocess.run([*READ_ONLY_ROOT, "true"], env=env, capture_output=True, check=False,
                               timeout=30)
    except FileNotFoundError:  # no unshare at all
        return False
    return probe.returncode == 0


def unavailable(reason: str) -> None:
    """Skip (fail in CI) because a read-only root cannot be made here."""
    skip_or_fail_in_ci(reason, f"the read-only root test cannot run in CI: {reason}")


def test_no_namespaces_skips_here_but_fails_in_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="cannot run in CI: no namespaces"):
        unavailable("no namespaces")
    monkeypatch.delenv("CI")
    with pytest.raises(pytest.skip.Exception, match="no namespaces"):
        unavailable("no namespaces")


def test_serves_from_a_read_only_root(double_model_path: Path, tmp_path: Path,
                                      demo_camera: FisheyeCamera) -> None:
    data = tmp_path / "registry"
    data.mkdir()
    if not _namespaces_allowed(data):
        unavailable("this machine does not allow mount namespaces (unshare --mount)")
    env = {"FISHLOC_DATA": str(data)}
    server = ServeProcess(serve_args(double_model_path, data / "cameras.db"), env, launcher=READ_ONLY_ROOT)
    with server:
        server.wait_ready()
        record = camera_to_dict(demo_camera) | {"id": "ro"}
        assert httpx.put(f"{server.url}/v1/cameras/ro", json=record).status_code == 201
        answer = httpx.post(f"{server.url}/v1/cameras/ro/detect", content=Samples(demo_camera).good_jpeg,
                            headers={"content-type": "image/jpeg"})
        assert answer.status_code == SCENARIO["read_only_root"].status and answer.json()["detections"]
    assert "Read-only file system" not in server.log and "Traceback" not in server.log
    assert not (data / "cameras.db").exists()  # it lived on the namespace's tmpfs, not on the disk
