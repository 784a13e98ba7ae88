"""Procedural benchmark frames: the requested size, real-frame file sizes, caching, folder loading."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from benchmarks.frames import FrameSpec, encode_jpeg, load_frames, make_frames, render_frame
from service.frame_decode import read_header


@pytest.mark.slow
def test_full_size_frame_has_a_camera_frames_byte_size(tmp_path: Path) -> None:
    spec = FrameSpec(size=2952, count=1)
    folder = make_frames(spec, tmp_path)
    frames = load_frames(folder)
    assert (frames.width, frames.height) == (2952, 2952)
    assert 1_500_000 <= frames.byte_sizes[0] <= 3_000_000, frames.byte_sizes


def test_frame_content_is_a_textured_fisheye_circle() -> None:
    spec = FrameSpec(size=512, count=1)
    bgr = render_frame(spec, 0)
    assert bgr.shape == (512, 512, 3) and bgr.dtype == np.uint8
    assert bgr[:8, :8].max() == 0 and bgr[-8:, -8:].max() == 0  # corners outside the image circle
    centre = bgr[192:320, 192:320].astype(np.float32)
    assert centre.mean() > 40 and centre.std() > 8  # lit and textured, not flat
    # Detail at several scales: a flat or blurred image would compress to a small fraction of this.
    assert len(encode_jpeg(bgr, 90)) > 512 * 512 * 3 * 0.08


def test_frames_are_cached_and_reproducible(tmp_path: Path) -> None:
    spec = FrameSpec(size=256, count=2, seed=3)
    folder = make_frames(spec, tmp_path)
    names = sorted(p.name for p in folder.iterdir())
    assert names == ["frame-000.jpg", "frame-001.jpg"]
    first = (folder / "frame-000.jpg").read_bytes()
    assert read_header(first).size_wh == (256, 256)
    (folder / "frame-001.jpg").unlink()
    make_frames(spec, tmp_path)  # re-renders only the missing frame, identically
    assert (folder / "frame-000.jpg").read_bytes() == first
    again = make_frames(FrameSpec(size=256, count=2, seed=3), tmp_path / "other")
    assert (again / "frame-001.jpg").read_bytes() == (folder / "frame-001.jpg").read_bytes()
    assert make_frames(FrameSpec(size=256, count=1, seed=4), tmp_path).name != folder.name


def test_load_frames_from_a_folder(tmp_path: Path) -> None:
    for index in range(3):
        image = np.full((40, 60, 3), 50 * index, dtype=np.uint8)
        cv2.imwrite(str(tmp_path / f"{index}.png" if index else tmp_path / "0.jpg"), image)
    (tmp_path / "notes.txt").write_text("not a frame")
    frames = load_frames(tmp_path)
    assert frames.names == ("0.jpg", "1.png", "2.png")
    assert (frames.width, frames.height, len(frames)) == (60, 40, 3)
    assert load_frames(tmp_path, limit=1).names == ("0.jpg",)


def test_load_frames_refuses_empty_and_mixed_folders(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no frames"):
        load_frames(tmp_path)
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((10, 10, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "b.png"), np.zeros((10, 20, 3), np.uint8))
    with pytest.raises(ValueError, match="several sizes"):
        load_frames(tmp_path)


@pytest.mark.parametrize("kwargs", [{"size": 10}, {"count": 0}, {"jpeg_quality": 0}, {"noise_sigma": -1.0}])
def test_frame_spec_refuses_nonsense(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        FrameSpec(**kwargs)  # type: ignore[arg-type]


def test_synth_frames_are_rendered_once(tmp_path: Path) -> None:
    from benchmarks.frames import make_synth_frames, synth_available

    if not synth_available():
        pytest.skip("this checkout has no `fishloc synth`")
    spec = FrameSpec(size=192, count=1, jpeg_quality=90)
    folder = make_synth_frames(spec, tmp_path)
    frames = load_frames(folder)
    assert (frames.width, frames.height, len(frames)) == (192, 192, 1)
    assert (folder / "annotations.json").exists()
    stamp = (folder / frames.names[0]).stat().st_mtime_ns
    assert make_synth_frames(spec, tmp_path) == folder
    assert (folder / frames.names[0]).stat().st_mtime_ns == stamp
