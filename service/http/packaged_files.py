"""Files shipped inside the package (the viewer, the API docs page) and served as they are, with a
Content-Security-Policy that lets a page load nothing from another origin: it works on a closed
network and cannot be made to call out."""

from __future__ import annotations

import threading
from pathlib import Path

from fastapi.responses import Response


class PackagedFiles:
    """The files of one folder, read once and answered with `content_security_policy`."""

    def __init__(self, folder: Path, content_security_policy: str) -> None:
        self.folder = folder
        self.headers = {"Content-Security-Policy": content_security_policy,
                        "X-Content-Type-Options": "nosniff", "Cache-Control": "no-cache"}
        self._contents: dict[str, bytes] = {}
        self._lock = threading.Lock()

    def has(self, name: str) -> bool:
        return (self.folder / name).is_file()

    def response(self, name: str, media_type: str) -> Response:
        """The file `name` (a name the caller has checked) as a response of `media_type`."""
        with self._lock:
            if name not in self._contents:
                self._contents[name] = (self.folder / name).read_bytes()
            content = self._contents[name]
        return Response(content, media_type=media_type, headers=self.headers)
