"""Benchmark frames: JPEGs with the size, detail and file size of real overhead fisheye frames.

Where the checkout has the synthetic renderer, `fishloc synth` renders them (unseen scenes through
the demo camera; `make_synth_frames`). The procedural frames below need nothing but OpenCV.

Decoding cost follows the encoded bytes (entropy decoding cannot be skipped, even at reduced DCT
scale), so a flat test image that compresses to 100 kB would make the decoder look ten times faster
than it is on a camera's 2 MB frame. These frames are procedural scenes seen through the demo
camera's lens (scaled to the frame size): a floor with multi-scale texture, tile seams, rugs,
furniture and people seen from above, far floor squeezed towards the image circle's rim, vignetting,
black outside the image circle and per-pixel sensor noise, encoded as camera firmware does
(quality 90, 4:2:0 chroma). Any folder of real frames can be used instead (`--frames DIR`).
"""

from __future__ import annotations

import argparse
import math
import shutil
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from benchmarks.checkout import checkout_env, source_root
from fisheye import FisheyeCamera, load_camera
from models import DEMO_CAMERA_PATH

FRAME_SUFFIXES = (".jpg", ".jpeg", ".png")
_TEXTURE_SIDE = 2048
_TEXTURE_PX_PER_M = 160.0
_ROOM_RADIUS_M = 6.0  # floor beyond this is squeezed towards the rim, like walls seen from above


@dataclass(frozen=True)
class FrameSpec:
    """What procedural frames to make: `count` frames of `size`×`size` px from `seed`."""

    size: int = 2952
    count: int = 6
    seed: int = 0
    jpeg_quality: int = 90
    noise_sigma: float = 6.0  # sensor noise, grey levels (the main driver of the file size)

    def __post_init__(self) -> None:
        if self.size < 64 or self.count < 1 or not 1 <= self.jpeg_quality <= 100 or self.noise_sigma < 0:
            raise ValueError(f"invalid frame spec {self}")

    @property
    def key(self) -> str:
        """A folder name that changes with every parameter (frames are cached under it)."""
        return f"{self.size}px-{self.count}f-seed{self.seed}-q{self.jpeg_quality}-n{self.noise_sigma:g}-v1"


def _octave_noise(rng: np.random.Generator, side: int, cells: tuple[int, ...]) -> NDArray[np.float32]:
    """(side, side) smooth noise in about [-1, 1]: random grids of `cells` per side, upsampled and summed."""
    total = np.zeros((side, side), dtype=np.float32)
    weight = 0.0
    for count, amplitude in zip(cells, np.geomspace(1.0, 0.25, len(cells)), strict=True):
        grid = rng.standard_normal((count, count)).astype(np.float32)
        total += float(amplitude) * cv2.resize(grid, (side, side), interpolation=cv2.INTER_CUBIC)
        weight += float(amplitude)
    return total / weight


def floor_texture(rng: np.random.Generator, side: int = _TEXTURE_SIDE) -> NDArray[np.uint8]:
    """(side, side, 3) BGR top view of a floor: textured tiles, rugs, furniture and people."""
    base = np.array(rng.uniform(90, 170, 3), dtype=np.float32)
    noise = _octave_noise(rng, side, (8, 32, 128, 512))
    grain = _octave_noise(rng, side, (1024,))
    texture = base[None, None, :] * (1.0 + 0.25 * noise[..., None] + 0.08 * grain[..., None])
    image = np.clip(texture, 0, 255).astype(np.uint8)
    tile = int(0.6 * _TEXTURE_PX_PER_M)
    for offset in range(tile // 2, side, tile):  # tile seams
        cv2.line(image, (offset, 0), (offset, side - 1), (60, 60, 60), 2, cv2.LINE_AA)
        cv2.line(image, (0, offset), (side - 1, offset), (60, 60, 60), 2, cv2.LINE_AA)
    for _ in range(int(rng.integers(6, 12))):  # rugs and furniture with their own texture
        w, h = (int(v) for v in rng.integers(80, 500, 2))
        x, y = (int(v) for v in rng.integers(0, side - 500, 2))
        color = rng.uniform(20, 235, 3)
        patch = _octave_noise(rng, 512, (4, 64, 256))[:h, :w, None]
        image[y:y + h, x:x + w] = np.clip(color * (1.0 + 0.35 * patch), 0, 255).astype(np.uint8)
        cv2.rectangle(image, (x, y), (x + w, y + h), tuple(float(c) * 0.4 for c in color), 3, cv2.LINE_AA)
    for _ in range(int(rng.integers(8, 20))):  # people from above: shoulders, head, shadow
        cx, cy = (int(v) for v in rng.integers(100, side - 100, 2))
        angle = float(rng.uniform(0, 180))
        cv2.ellipse(image, (cx + 12, cy + 12), (40, 26), angle, 0, 360, (40, 40, 40), -1, cv2.LINE_AA)
        clothes = tuple(float(c) for c in rng.uniform(10, 245, 3))
        cv2.ellipse(image, (cx, cy), (38, 24), angle, 0, 360, clothes, -1, cv2.LINE_AA)
        cv2.circle(image, (cx, cy), 15, tuple(float(c) for c in rng.uniform(10, 90, 3)), -1, cv2.LINE_AA)
    return image


def _fisheye_maps(camera: FisheyeCamera, size: int) -> tuple[NDArray[np.float32], NDArray[np.float32],
                                                              NDArray[np.float32]]:
    """Texture coordinates (map_x, map_y) and a brightness gain (0 outside the image circle) per pixel.

    Computed on a coarse grid and upsampled: the maps are smooth, and inverting the lens for every
    one of 8.7 million pixels would take longer than the rest of the frame.
    """
    coarse = max(64, size // 8)
    step = size / coarse
    centres = (np.arange(coarse) + 0.5) * step - 0.5
    u, v = np.meshgrid(centres, centres)
    theta, phi = camera.pixels_to_angles(np.stack([u.ravel(), v.ravel()], axis=1))
    theta = np.nan_to_num(theta, nan=math.pi).reshape(coarse, coarse)
    phi = np.nan_to_num(phi).reshape(coarse, coarse)
    distance_m = camera.altitude_m * np.tan(np.minimum(theta, math.radians(89.0)))
    squeezed_m = _ROOM_RADIUS_M * np.tanh(distance_m / _ROOM_RADIUS_M)
    centre = _TEXTURE_SIDE / 2
    map_x = centre + squeezed_m * np.cos(phi) * _TEXTURE_PX_PER_M
    map_y = centre - squeezed_m * np.sin(phi) * _TEXTURE_PX_PER_M
    rim = math.radians(min(camera.theta_max_deg, 95.0))
    gain = np.clip((rim - theta) / math.radians(1.0), 0.0, 1.0) * (0.55 + 0.45 * np.cos(theta) ** 2)
    def upsampled(values: NDArray[np.float64]) -> NDArray[np.float32]:
        full = cv2.resize(values.astype(np.float32), (size, size), interpolation=cv2.INTER_LINEAR)
        return np.asarray(full, dtype=np.float32)

    return upsampled(map_x), upsampled(map_y), upsampled(gain)


def render_frame(spec: FrameSpec, index: int, camera: FisheyeCamera | None = None) -> NDArray[np.uint8]:
    """Frame `index` of `spec` as a (size, size, 3) BGR image."""
    rng = np.random.default_rng([spec.seed, index])
    cam = (camera or load_camera(DEMO_CAMERA_PATH)).scaled_to((spec.size, spec.size))
    map_x, map_y, gain = _fisheye_maps(cam, spec.size)
    texture = floor_texture(rng)
    view = cv2.remap(texture, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    shaded = view.astype(np.float32) * gain[..., None]
    if spec.noise_sigma > 0:
        # Luma noise shared by the channels plus weaker chroma noise, as a Bayer sensor's demosaic gives.
        luma = rng.standard_normal(gain.shape, dtype=np.float32) * spec.noise_sigma
        shaded += luma[..., None]
        shaded += rng.standard_normal(shaded.shape, dtype=np.float32) * (spec.noise_sigma * 0.4)
        shaded *= (gain > 0)[..., None]
    return np.clip(shaded, 0, 255).astype(np.uint8)


def encode_jpeg(bgr: NDArray[np.uint8], quality: int) -> bytes:
    ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise RuntimeError("OpenCV could not encode the frame")
    return bytes(data.tobytes())


def default_cache_dir() -> Path:
    return Path.home() / ".cache" / "fishloc" / "bench-frames"


def make_frames(spec: FrameSpec, cache_dir: Path | None = None) -> Path:
    """The folder of `spec`'s frames (`frame-000.jpg`, ...), rendering those not cached yet."""
    folder = (cache_dir or default_cache_dir()) / spec.key
    folder.mkdir(parents=True, exist_ok=True)
    camera = load_camera(DEMO_CAMERA_PATH)
    for index in range(spec.count):
        path = folder / f"frame-{index:03d}.jpg"
        if not path.exists():
            temporary = path.with_suffix(".tmp")
            temporary.write_bytes(encode_jpeg(render_frame(spec, index, camera), spec.jpeg_quality))
            temporary.replace(path)
    return folder


def synth_available() -> bool:
    """Whether this checkout has the synthetic renderer (`fishloc synth`)."""
    from service.cli import COMMANDS

    return "synth" in COMMANDS


def make_synth_frames(spec: FrameSpec, cache_dir: Path | None = None, camera_path: Path = DEMO_CAMERA_PATH
                      ) -> Path:
    """The folder of `spec.count` frames of unseen synthetic scenes rendered by `fishloc synth` (people,
    furniture, textures, sensor noise; `annotations.json` beside them) through `camera_path`,
    rendering them on first use. `spec.noise_sigma` is the procedural generator's and is not used."""
    folder = (cache_dir or default_cache_dir()) / (
        f"synth-{spec.size}px-{spec.count}f-seed{spec.seed}-q{spec.jpeg_quality}-{Path(camera_path).stem}-v1")
    if (folder / "annotations.json").exists():
        return folder
    staging = folder.with_name(folder.name + ".partial")
    shutil.rmtree(staging, ignore_errors=True)
    command = [sys.executable, "-m", "service.cli", "synth", "--out", str(staging),
               "--images", str(spec.count), "--size", str(spec.size), "--seed", str(spec.seed),
               "--split", "unseen", "--camera", str(Path(camera_path).resolve()),
               "--jpeg-quality", str(spec.jpeg_quality), "--quiet"]
    done = subprocess.run(command, capture_output=True, text=True, check=False, cwd=source_root(),
                          env=checkout_env())
    if done.returncode != 0:
        raise RuntimeError(f"fishloc synth failed ({done.returncode}): {done.stderr.strip()[-500:]}")
    staging.replace(folder)
    return folder


@dataclass(frozen=True)
class FrameSet:
    """Encoded frames to send: their bytes, names and pixel size (all frames share one size)."""

    folder: str
    names: tuple[str, ...]
    data: tuple[bytes, ...]
    width: int
    height: int

    @property
    def byte_sizes(self) -> list[int]:
        return [len(d) for d in self.data]

    def __len__(self) -> int:
        return len(self.data)


def load_frames(folder: str | Path, limit: int | None = None) -> FrameSet:
    """The JPEG/PNG frames of a folder (sorted by name); ValueError when there are none or their
    sizes differ (one benchmark camera has one resolution)."""
    from service.frame_decode import read_header

    root = Path(folder)
    files = sorted(p for p in root.iterdir() if p.suffix.lower() in FRAME_SUFFIXES)[:limit]
    if not files:
        raise ValueError(f"no frames (.jpg, .jpeg, .png) in {root}")
    data = tuple(p.read_bytes() for p in files)
    sizes = {read_header(d).size_wh for d in data}
    if len(sizes) != 1:
        raise ValueError(f"the frames of {root} have several sizes {sorted(sizes)}; use frames of one camera")
    (width, height), = sizes
    return FrameSet(str(root), tuple(p.name for p in files), data, width, height)


def bench_frames(args: argparse.Namespace, progress: Callable[[str], object] = print) -> FrameSet:
    """The frames a benchmark run uses: `--frames DIR`, or rendered (and cached) per `--frame-size`,
    `--frame-count`, `--renderer` and `--camera`."""
    if args.frames is not None:
        return load_frames(args.frames)
    spec = FrameSpec(size=args.frame_size, count=args.frame_count)
    renderer = args.renderer or ("synth" if synth_available() else "procedural")
    if renderer == "synth":
        progress(f"frames: {spec.count} unseen {spec.size}×{spec.size} scenes by `fishloc synth` "
                 "(rendered once, then cached; minutes on 2 cores)")
        return load_frames(make_synth_frames(spec, camera_path=args.camera))
    progress(f"frames: rendering/caching {spec.count} procedural {spec.size}×{spec.size} JPEGs ({spec.key})")
    return load_frames(make_frames(spec))
