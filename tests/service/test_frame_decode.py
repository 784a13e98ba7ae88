"""Header reading, reduced-scale decoding and the decoded-pixel limit."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest

from service.frame_decode import FrameError, decode_frame, pick_reduction, read_header


def _jpeg(width: int, height: int, progressive: bool = False) -> bytes:
    image = np.random.default_rng(0).integers(0, 255, (height, width, 3), dtype=np.uint8)
    params = [cv2.IMWRITE_JPEG_PROGRESSIVE, 1] if progressive else []
    return bytes(cv2.imencode(".jpg", image, params)[1].tobytes())


def _png_claiming(width: int, height: int) -> bytes:
    """A tiny PNG whose header claims `width`x`height` (a decompression bomb's first bytes)."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    chunk = struct.pack(">I", len(ihdr)) + b"IHDR" + ihdr + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))
    return b"\x89PNG\r\n\x1a\n" + chunk + bytes(64)


def _jpeg_claiming(width: int, height: int) -> bytes:
    """A small real JPEG with its frame header's size rewritten."""
    data = bytearray(_jpeg(16, 16))
    sof = data.find(b"\xff\xc0")
    data[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


@pytest.mark.parametrize(("width", "height", "progressive"), [(1, 1, False), (640, 480, False),
                                                              (333, 517, True), (2048, 2048, False)])
def test_jpeg_header_size(width: int, height: int, progressive: bool) -> None:
    header = read_header(_jpeg(width, height, progressive))
    assert (header.format, header.width, header.height) == ("jpeg", width, height)


def test_png_header_size() -> None:
    data = bytes(cv2.imencode(".png", np.zeros((37, 91, 3), dtype=np.uint8))[1].tobytes())
    header = read_header(data)
    assert (header.format, header.size_wh) == ("png", (91, 37))


@pytest.mark.parametrize(("frame_wh", "size", "expected"), [
    ((100, 100), 256, 1),        # smaller than the input
    ((2048, 2048), 256, 8),
    ((2048, 2048), 512, 4),
    ((2048, 2048), 640, 2),      # 1024 >= 640 but 512 < 640
    ((2952, 2952), 512, 4),      # 738 >= 512
    ((1920, 1080), 512, 2),
    ((2050, 2050), 256, 2),      # 2050 is not divisible by 4 or 8
    ((2047, 2047), 256, 1),
])
def test_pick_reduction(frame_wh: tuple[int, int], size: int, expected: int) -> None:
    assert pick_reduction(frame_wh, size) == expected


def test_reduced_decode_matches_area_downscale() -> None:
    rng = np.random.default_rng(1)
    small = rng.integers(0, 255, (64, 64, 3), dtype=np.uint8)
    big = cv2.resize(small, (512, 512), interpolation=cv2.INTER_NEAREST)
    data = bytes(cv2.imencode(".jpg", big, [cv2.IMWRITE_JPEG_QUALITY, 100])[1].tobytes())
    frame = decode_frame(data, input_size=64, max_pixels=10**7)
    assert frame.reduction == 8 and frame.decoded_wh == (64, 64) and frame.frame_wh == (512, 512)
    rgb_small = cv2.cvtColor(small, cv2.COLOR_BGR2RGB).astype(np.int16)
    assert np.abs(frame.rgb.astype(np.int16) - rgb_small).mean() < 4  # JPEG noise only


@pytest.mark.parametrize("data", [_png_claiming(100_000, 100_000), _jpeg_claiming(60_000, 60_000)])
def test_decompression_bomb_is_refused_from_the_header(data: bytes) -> None:
    with pytest.raises(FrameError) as caught:
        decode_frame(data, input_size=256, max_pixels=40_000_000)
    assert caught.value.code == "image_too_large"


@pytest.mark.parametrize(("data", "code"), [
    (b"", "empty_body"),
    (b"BM" + bytes(60), "unsupported_image"),
    (b"\xff\xd8\xff\xd9", "bad_image"),
    (b"\x89PNG\r\n\x1a\n" + bytes(4), "bad_image"),
])
def test_unreadable_headers(data: bytes, code: str) -> None:
    with pytest.raises(FrameError) as caught:
        read_header(data)
    assert caught.value.code == code
