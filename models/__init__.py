"""Assets shipped with FishLoc: the default ONNX model, its model card, and the `demo` camera.

Installed as package data, so `fishloc serve` finds them from any folder after `pip install .`.
"""

from __future__ import annotations

from pathlib import Path

ASSETS_DIR = Path(__file__).resolve().parent
DEFAULT_MODEL_PATH = ASSETS_DIR / "fishloc-default.onnx"
DEMO_CAMERA_PATH = ASSETS_DIR / "demo_camera.yaml"
