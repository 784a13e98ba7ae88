"""`python -m benchmarks.decode`: both decoders timed on one camera's frames at the service's scale."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from benchmarks.decode import main


def _frames(folder: Path, side: int, count: int) -> Path:
    folder.mkdir()
    rng = np.random.default_rng(3)
    for index in range(count):
        image = cv2.GaussianBlur(rng.integers(0, 255, (side, side, 3), dtype=np.uint8), (9, 9), 3)
        cv2.imwrite(str(folder / f"{index:06d}.jpg"), image)
    return folder


def test_rows_per_folder_and_budget(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    frames = _frames(tmp_path / "frames", 1024, 2)
    out = tmp_path / "decode.json"
    assert main(["--frames", str(frames), "--budget", "800000", "--budget", "1000000", "--runs", "20",
                 "--json", str(out)]) == 0
    record = json.loads(out.read_text())
    assert "logical CPUs" in record["machine"]
    assert [row["budget"] for row in record["rows"]] == [800000, 1000000]
    for row in record["rows"]:
        assert row["frame_wh"] == [1024, 1024] and row["reduction"] in (1, 2, 4, 8)
        for name in ("opencv", "turbojpeg"):
            summary = row["ms"][name]
            assert 0 < summary["min"] <= summary["p50"] <= summary["p95"] <= summary["p99"] <= summary["max"]
        assert row["p50_ratio"] == pytest.approx(row["ms"]["turbojpeg"]["p50"] / row["ms"]["opencv"]["p50"])
    assert capsys.readouterr().out.count("| 1024x1024 |") == 2


def test_too_few_runs_are_refused(tmp_path: Path) -> None:
    with pytest.raises(SystemExit):
        main(["--frames", str(_frames(tmp_path / "frames", 64, 1)), "--runs", "5"])
