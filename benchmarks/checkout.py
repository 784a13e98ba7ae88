"""Running `python -m service.cli ...` subprocesses on this very checkout.

An installed (possibly editable) FishLoc elsewhere on the machine must not answer for the code being
measured: the subprocess runs in the folder that holds the imported `service` package, with that
folder first on PYTHONPATH.
"""

from __future__ import annotations

import os
from pathlib import Path

import service


def source_root() -> Path:
    """The folder holding the `service` package this process imported."""
    return Path(service.__file__).resolve().parent.parent


def checkout_env(extra: dict[str, str] | None = None) -> dict[str, str]:
    """This process's environment with `source_root()` first on PYTHONPATH, plus `extra`."""
    paths = [str(source_root()), os.environ.get("PYTHONPATH", "")]
    return dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in paths if p), **(extra or {}))
