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
    assert frame.scale_xy == (1 / 8, 1 / 8)  # decoded px per frame px, what the second look samples at
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


def _photo_jpeg(width: int, height: int, **params: int) -> bytes:
    """A smooth picture with edges (JPEG's usual content, unlike noise) encoded with `params`."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    image = np.stack([127 + 120 * np.sin(x / 23), 127 + 120 * np.cos(y / 17), (x + y) % 256], -1)
    image[height // 3:height // 2, width // 4:width // 2] = (20, 200, 90)
    flags = [number for key, value in params.items() for number in (getattr(cv2, key), value)]
    return bytes(cv2.imencode(".jpg", image.astype(np.uint8), flags)[1].tobytes())


@pytest.mark.parametrize(("params", "reduction"), [
    ({}, 1), ({}, 2), ({}, 4), ({}, 8),
    ({"IMWRITE_JPEG_PROGRESSIVE": 1}, 4),
    ({"IMWRITE_JPEG_SAMPLING_FACTOR": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444}, 2),
    ({"IMWRITE_JPEG_SAMPLING_FACTOR": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422}, 2),
])
def test_turbo_decode_gives_opencvs_pixels(params: dict[str, int], reduction: int) -> None:
    """The TurboJPEG decode is OpenCV's reduced decode and colour swap, bit for bit."""
    data = _photo_jpeg(1024, 768, **params)
    frame = decode_frame(data, input_size=1024 // reduction, max_pixels=10**7)
    assert frame.reduction == reduction
    modes = {1: cv2.IMREAD_COLOR, 2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4,
             8: cv2.IMREAD_REDUCED_COLOR_8}
    flags = cv2.IMREAD_IGNORE_ORIENTATION | modes[reduction]
    expected = cv2.cvtColor(cv2.imdecode(np.frombuffer(data, np.uint8), flags), cv2.COLOR_BGR2RGB)
    assert frame.rgb.shape == expected.shape and np.array_equal(frame.rgb, expected)


def test_grey_jpeg_decodes_to_three_equal_channels() -> None:
    grey = cv2.cvtColor(cv2.imdecode(np.frombuffer(_photo_jpeg(320, 240), np.uint8), cv2.IMREAD_COLOR),
                        cv2.COLOR_BGR2GRAY)
    data = bytes(cv2.imencode(".jpg", grey)[1].tobytes())
    frame = decode_frame(data, input_size=320, max_pixels=10**7)
    assert frame.rgb.shape == (240, 320, 3)
    red, green, blue = (frame.rgb[..., k] for k in range(3))
    assert np.array_equal(red, green) and np.array_equal(green, blue)


def test_a_jpeg_turbojpeg_refuses_goes_to_opencv(monkeypatch: pytest.MonkeyPatch) -> None:
    """A truncated JPEG (TurboJPEG refuses it outright) is answered as OpenCV's decoder answers it."""
    import service.frame_decode as frame_decode

    data = _photo_jpeg(640, 480)
    truncated = data[:len(data) * 2 // 3]
    calls: list[int] = []
    real = frame_decode.simplejpeg.decode_jpeg
    with pytest.raises(ValueError):
        real(truncated, "RGB")

    def counting(*args: object, **kwargs: object) -> object:
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(frame_decode.simplejpeg, "decode_jpeg", counting)
    flags = cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION
    expected = cv2.imdecode(np.frombuffer(truncated, np.uint8), flags)
    if expected is None:
        with pytest.raises(FrameError) as caught:
            decode_frame(truncated, input_size=640, max_pixels=10**7)
        assert caught.value.code == "bad_image"
    else:
        frame = decode_frame(truncated, input_size=640, max_pixels=10**7)
        assert np.array_equal(frame.rgb, cv2.cvtColor(expected, cv2.COLOR_BGR2RGB))
    assert calls == [1]
