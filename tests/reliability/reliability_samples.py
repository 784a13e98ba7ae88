"""Encoded frames for the bad-input cases: good ones of the demo camera with a person at a known
floor position (in several encodings), and bad ones (corrupt, truncated, bombs, wrong shapes)."""

from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from numpy.typing import NDArray
from PIL import Image
from reliability_support import encode, person_frame

from fisheye import FisheyeCamera

PERSON_FLOOR_XY_M = (1.2, -0.8)
FRAME_WH = (1024, 1024)  # the demo camera is calibrated at 2048x2048: same aspect ratio


def _png_chunk(kind: bytes, payload: bytes) -> bytes:
    return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))


def png_claiming(width: int, height: int) -> bytes:
    """A 100-byte PNG whose header claims `width`x`height` (a decompression bomb's first bytes)."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + bytes(64)


def png_zero_bomb(side: int) -> bytes:
    """A complete, valid PNG of side x side black RGB pixels: tiny on the wire, large decoded."""
    ihdr = struct.pack(">IIBBBBB", side, side, 8, 2, 0, 0, 0)
    compressor = zlib.compressobj(9)
    row = bytes(1 + 3 * side)  # filter byte 0 + black pixels
    idat = b"".join(compressor.compress(row) for _ in range(side)) + compressor.flush()
    chunks = _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", idat) + _png_chunk(b"IEND", b"")
    return b"\x89PNG\r\n\x1a\n" + chunks


def jpeg_claiming(width: int, height: int) -> bytes:
    """A small real JPEG with its frame header's size rewritten."""
    data = bytearray(encode(np.zeros((16, 16, 3), np.uint8)))
    sof = data.find(b"\xff\xc0")
    data[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def _png(image: NDArray[np.generic]) -> bytes:
    ok, data = cv2.imencode(".png", image)
    assert ok
    return bytes(data.tobytes())


@dataclass
class Samples:
    """Frames of `camera` (the demo camera), made once per test module."""

    camera: FisheyeCamera

    @cached_property
    def person_bgr(self) -> NDArray[np.uint8]:
        return np.asarray(person_frame(self.camera, PERSON_FLOOR_XY_M, FRAME_WH, disk_radius_px=20).bgr)

    @cached_property
    def good_jpeg(self) -> bytes:
        return bytes(encode(self.person_bgr))

    @property
    def png_16bit(self) -> bytes:
        return _png(self.person_bgr.astype(np.uint16) * 257)

    @property
    def png_gray(self) -> bytes:
        return _png(cv2.cvtColor(self.person_bgr, cv2.COLOR_BGR2GRAY))

    @property
    def png_gray_16bit(self) -> bytes:
        return _png(cv2.cvtColor(self.person_bgr, cv2.COLOR_BGR2GRAY).astype(np.uint16) * 257)

    @property
    def png_rgba(self) -> bytes:
        alpha = np.full((*self.person_bgr.shape[:2], 1), 128, np.uint8)  # half transparent everywhere
        return _png(np.concatenate([self.person_bgr, alpha], axis=2))

    @property
    def png_palette(self) -> bytes:
        rgb = cv2.cvtColor(self.person_bgr, cv2.COLOR_BGR2RGB)
        buffer = io.BytesIO()
        Image.fromarray(rgb).quantize(16).save(buffer, "PNG")
        return buffer.getvalue()

    @property
    def jpeg_cmyk(self) -> bytes:
        rgb = cv2.cvtColor(self.person_bgr, cv2.COLOR_BGR2RGB)
        buffer = io.BytesIO()
        Image.fromarray(rgb).convert("CMYK").save(buffer, "JPEG", quality=95)
        data = buffer.getvalue()
        assert Image.open(io.BytesIO(data)).mode == "CMYK"
        return data

    @property
    def jpeg_progressive(self) -> bytes:
        ok, data = cv2.imencode(".jpg", self.person_bgr, [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])
        assert ok
        return bytes(data.tobytes())

    @property
    def jpeg_truncated(self) -> bytes:
        return self.good_jpeg[: len(self.good_jpeg) // 2]

    @property
    def jpeg_header_only(self) -> bytes:
        data = self.good_jpeg
        return data[: data.find(b"\xff\xda") + 2]  # up to the start of scan, no picture data

    @property
    def png_truncated(self) -> bytes:
        data = _png(self.person_bgr)
        return data[: len(data) // 2]

    @property
    def random_bytes(self) -> bytes:
        return np.random.default_rng(10).integers(0, 256, 4096, dtype=np.uint8).tobytes()

    @property
    def random_after_jpeg_magic(self) -> bytes:
        return b"\xff\xd8\xff" + self.random_bytes

    @staticmethod
    def black_jpeg(width: int, height: int) -> bytes:
        return bytes(encode(np.zeros((height, width, 3), np.uint8)))

    @staticmethod
    def multipart(field: str, payload: bytes, boundary: str = "fishloc-boundary") -> bytes:
        return (
            f"--{boundary}\r\nContent-Disposition: form-data; name=\"{field}\"; filename=\"f.jpg\"\r\n"
            f"Content-Type: image/jpeg\r\n\r\n".encode() + payload + f"\r\n--{boundary}--\r\n".encode()
        )
