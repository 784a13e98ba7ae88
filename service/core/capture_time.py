"""`capture_time` of a frame: when the camera took it, the only clock of site tracking (DESIGN.md).

REST takes Unix seconds (`1764612345.2`) or RFC 3339 (`2025-12-01T18:05:45.2Z`, an offset required);
gRPC a `google.protobuf.Timestamp`. Without one, a frame's capture time is its arrival time.
"""

from __future__ import annotations

import math
import re
from datetime import datetime

# Years 1970 to 2999: anything else is a unit mistake (milliseconds, say), not a time.
MAX_UNIX_S = 32_503_680_000.0
_RFC3339 = re.compile(r"^\d{4}-\d{2}-\d{2}[Tt ]\d{2}:\d{2}:\d{2}(\.\d{1,9})?([Zz]|[+-]\d{2}:\d{2})$")


class CaptureTimeError(ValueError):
    """A capture time that is not a time; the message says what is expected."""


def check_unix_s(seconds: float) -> float:
    if not math.isfinite(seconds) or not 0.0 <= seconds < MAX_UNIX_S:
        raise CaptureTimeError(f"capture_time must be Unix seconds between 1970 and 2999, got {seconds!r}")
    return seconds


def parse_capture_time(text: str) -> float:
    """Unix seconds from `text`: a number of Unix seconds or an RFC 3339 date-time with its offset."""
    value = text.strip()
    if _RFC3339.fullmatch(value):
        try:
            moment = datetime.fromisoformat(value.upper().replace("Z", "+00:00"))
        except ValueError as error:
            raise CaptureTimeError(f"capture_time {text!r} is not a valid date-time: {error}") from None
        return check_unix_s(moment.timestamp())
    try:
        seconds = float(value)
    except ValueError:
        raise CaptureTimeError(
            f"capture_time {text[:64]!r} is neither Unix seconds (e.g. 1764612345.2) nor an RFC 3339 "
            "date-time with an offset (e.g. 2025-12-01T18:05:45.2Z)") from None
    return check_unix_s(seconds)
