"""A short synthetic sequence of the built-in site and a real server of the shipped model, for the
tests that play a sequence through the service."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from service_live_server import LiveServer

from detector.data.sequence import SequenceConfig
from detector.data.sequence_writer import write_sequence
from detector.data.site_world import default_plan
from models import DEFAULT_MODEL_PATH
from service.core.config import Settings


def render_sequence(folder: Path, steps: int, seed: int, size: int = 512) -> Path:
    """Render `steps` steps at 5 fps of the built-in site into `folder`; its annotations.json."""
    write_sequence(folder, SequenceConfig(plan=default_plan(), steps=steps, fps=5.0, seed=seed, size=size))
    return folder / "annotations.json"


@contextmanager
def shipped_model_server(folder: Path) -> Iterator[LiveServer]:
    """A real server of the shipped model on a loopback port, with a fresh registry in `folder`."""
    settings = Settings(model=DEFAULT_MODEL_PATH, database=str(folder / "cameras.db"), http_port=0,
                        grpc_port=-1, threads=1, demo_camera=False)
    with LiveServer(settings) as live:
        yield live
