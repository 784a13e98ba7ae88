"""Decoding encoded frames safely and cheaply.

The size is read from the JPEG/PNG header before anything is decoded, so a small file that claims a
huge picture (a decompression bomb) is refused without allocating it. A JPEG much larger than the
model input is decoded at 1/2, 1/4 or 1/8 scale by libjpeg's DCT scaling, which skips most of the
decoding work instead of decoding every pixel and then throwing most of them away.

JPEGs are decoded by libjpeg-turbo's TurboJPEG API (simplejpeg), straight to RGB and with the GIL
released: the same pixels as OpenCV's decoder bit for bit, in less time (2952 x 2952 renders at
1/2 scale: 14.4 against 18.3 ms p50 with OpenCV's decode and colour swap; README, "Benchmark"). A JPEG
it refuses (truncated, or a recoverable error it treats as fatal) goes to OpenCV's decoder, which
answers as it always has.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
import simplejpeg
from numpy.typing import NDArray

ImageFormat = Literal["jpeg", "png"]

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# Start-of-frame markers carry the picture size; C4 (DHT), C8 (JPG) and CC (DAC) are not frames.
_SOF_MARKERS = frozenset({0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF})
_REDUCED_FLAGS = {2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4, 8: cv2.IMREAD_REDUCED_COLOR_8}
# EXIF orientation is ignored: a camera's calibration describes the sensor's pixels as sent.
_BASE_FLAGS = cv2.IMREAD_IGNORE_ORIENTATION


class FrameError(ValueError):
    """An encoded frame that cannot be used; `code` says why (for API error answers)."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


@dataclass(frozen=True)
class FrameHeader:
    """What the header of an encoded frame says: its format and size in pixels."""

    format: ImageFormat
    width: int
    height: int

    @property
    def size_wh(self) -> tuple[int, int]:
        return self.width, self.height


@dataclass(frozen=True)
class DecodedFrame:
    """A decoded frame: `rgb` (h, w, 3) uint8 at 1/`reduction` of the encoded size `frame_wh`."""

    rgb: NDArray[np.uint8]
    frame_wh: tuple[int, int]
    reduction: int

    def __post_init__(self) -> None:
        if self.rgb.ndim != 3 or self.rgb.shape[2] != 3 or self.rgb.dtype != np.uint8:
            raise ValueError(f"rgb must be (h, w, 3) uint8, got {self.rgb.shape} {self.rgb.dtype}")

    @property
    def decoded_wh(self) -> tuple[int, int]:
        return int(self.rgb.shape[1]), int(self.rgb.shape[0])

    @property
    def scale_xy(self) -> tuple[float, float]:
        """The decoded px per frame px, x and y (what the second look samples its patches at)."""
        return self.rgb.shape[1] / self.frame_wh[0], self.rgb.shape[0] / self.frame_wh[1]


def _jpeg_size(data: bytes) -> tuple[int, int]:
    position = 2
    while position + 4 <= len(data):
        if data[position] != 0xFF:
            raise FrameError("bad_image", "corrupt JPEG: marker expected")
        marker = data[position + 1]
        if marker == 0xFF:  # fill byte
            position += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # markers without a length
            position += 2
            continue
        (length,) = struct.unpack(">H", data[position + 2:position + 4])
        if length < 2:
            raise FrameError("bad_image", "corrupt JPEG: bad segment length")
        if marker in _SOF_MARKERS:
            if position + 9 > len(data):
                break
            height, width = struct.unpack(">HH", data[position + 5:position + 9])
            return width, height
        if marker in (0xD9, 0xDA):  # end of image or start of scan before any frame header
            break
        position += 2 + length
    raise FrameError("bad_image", "corrupt JPEG: no frame header")


def _png_size(data: bytes) -> tuple[int, int]:
    if len(data) < 24 or data[12:16] != b"IHDR":
        raise FrameError("bad_image", "corrupt PNG: no IHDR chunk")
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def read_header(data: bytes) -> FrameHeader:
    """Format and size of a JPEG or PNG frame from its first bytes; FrameError otherwise."""
    if data[:3] == b"\xff\xd8\xff":
        image_format: ImageFormat = "jpeg"
        width, height = _jpeg_size(data)
    elif data[:8] == _PNG_SIGNATURE:
        image_format = "png"
        width, height = _png_size(data)
    elif not data:
        raise FrameError("empty_body", "the request has no image")
    else:
        raise FrameError("unsupported_image", "the image is neither JPEG nor PNG")
    if width < 1 or height < 1:
        raise FrameError("bad_image", f"the image header gives an empty size {width}x{height}")
    return FrameHeader(image_format, width, height)


def check_frame_size(header: FrameHeader, max_pixels: int, min_side_px: int = 1) -> None:
    """Refuse, from the header alone, a frame of more than `max_pixels` pixels (`image_too_large`:
    nothing is allocated for it) or with a side under `min_side_px` (`frame_too_small`)."""
    if header.width * header.height > max_pixels:
        raise FrameError(
            "image_too_large",
            f"the image is {header.width}x{header.height} = {header.width * header.height} pixels; "
            f"the limit is {max_pixels}",
        )
    if min(header.size_wh) < min_side_px:
        raise FrameError(
            "frame_too_small",
            f"the image is {header.width}x{header.height}; frames need at least {min_side_px} px a side",
        )


def pick_reduction(frame_wh: tuple[int, int], input_size: int) -> int:
    """Largest DCT reduction (1, 2, 4 or 8) that keeps the frame's long side ≥ `input_size` and
    divides both sides exactly (so reduced pixels map back to frame pixels without rounding)."""
    width, height = frame_wh
    for factor in (8, 4, 2):
        if max(width, height) // factor >= input_size and width % factor == 0 and height % factor == 0:
            return factor
    return 1


def decode_frame(data: bytes, input_size: int, max_pixels: int,
                 header: FrameHeader | None = None) -> DecodedFrame:
    """Encoded JPEG/PNG bytes -> RGB frame, reduced in scale where the model input allows it.

    FrameError codes: `unsupported_image` (neither JPEG nor PNG), `image_too_large` (the header
    gives more than `max_pixels`), `bad_image` (corrupt or truncated). `header` is `read_header(data)`
    when the caller has read it already.
    """
    header = read_header(data) if header is None else header
    check_frame_size(header, max_pixels)
    reduction = pick_reduction(header.size_wh, input_size) if header.format == "jpeg" else 1
    rgb = _turbo_decode(data, header, reduction) if header.format == "jpeg" else None
    if rgb is None:
        rgb = decode_with_opencv(data, header, reduction)
    return DecodedFrame(rgb=rgb, frame_wh=header.size_wh, reduction=reduction)


def _turbo_decode(data: bytes, header: FrameHeader, reduction: int) -> NDArray[np.uint8] | None:
    """A JPEG decoded by TurboJPEG at 1/`reduction` scale (libjpeg's scaled size is the header's
    divided exactly, so asking for that size picks the same DCT scaling as OpenCV's reduced modes);
    None where TurboJPEG refuses it or gives another size."""
    expected_wh = (header.width // reduction, header.height // reduction)
    try:
        rgb = simplejpeg.decode_jpeg(data, "RGB", min_width=expected_wh[0], min_height=expected_wh[1])
    except ValueError:
        return None
    if (rgb.shape[1], rgb.shape[0]) != expected_wh or rgb.ndim != 3 or rgb.shape[2] != 3:
        return None
    return np.ascontiguousarray(rgb, dtype=np.uint8)


def decode_with_opencv(data: bytes, header: FrameHeader, reduction: int) -> NDArray[np.uint8]:
    """A JPEG or PNG decoded by OpenCV at 1/`reduction` scale (a JPEG's DCT scaling); FrameError
    `bad_image` where it cannot be."""
    flags = _BASE_FLAGS | (_REDUCED_FLAGS[reduction] if reduction > 1 else cv2.IMREAD_COLOR)
    buffer = np.frombuffer(data, dtype=np.uint8)
    try:
        bgr = cv2.imdecode(buffer, flags)
    except cv2.error as error:
        raise FrameError("bad_image", f"cannot decode the {header.format.upper()} image: {error}") from None
    if bgr is None:
        raise FrameError("bad_image", f"cannot decode the {header.format.upper()} image")
    expected_wh = (header.width // reduction, header.height // reduction)
    if (bgr.shape[1], bgr.shape[0]) != expected_wh:
        raise FrameError(
            "bad_image",
            f"the image decodes to {bgr.shape[1]}x{bgr.shape[0]}, its header says "
            f"{header.width}x{header.height}",
        )
    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(rgb, dtype=np.uint8)
