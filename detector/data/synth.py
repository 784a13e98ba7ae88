"""One synthetic frame: scene, people, light, render, ground truth, sensor, JPEG.

Frame `index` of a data set with seed `seed` is made from its own random generator, seeded from
(seed, split, index), so a frame is the same whichever process makes it and in whatever order.
Its scene is scene `index // images_per_scene` of the split (seeded from split and scene index
only), so data sets made with different seeds share the split's scenes but not their frames.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from detector.data.body import build_person
from detector.data.crowd import place_people, sample_count
from detector.data.environment import Background, trace_environment
from detector.data.ground_truth import PersonTruth, people_truth
from detector.data.palettes import SPLITS
from detector.data.rays import ray_grid
from detector.data.render import Group, Lighting, StaticScene, render, render_static
from detector.data.scenes import Scene, build_scene
from detector.data.sensor import develop, encode_jpeg, sample_sensor
from fisheye import FisheyeCamera

FloatArray = NDArray[np.float64]
BOX_KINDS = ("visible", "whole")  # `SynthConfig.boxes`, `fishloc synth --boxes`


@dataclass(frozen=True)
class SynthConfig:
    """What to render: frame side `size` px (square), `kind` (indoor/outdoor, None for both) or
    scene `style`s (comma-separated; scene i gets the (i mod count)-th),
    `people` (min, max) per frame (None: the default mix of 0-60), a fixed `camera` (None: each
    scene's own), `images_per_scene`, and the visibility under which a person is only an
    ignore region (`min_visible_fraction`, `min_visible_px`); `boxes` "visible" (the visible
    silhouette's, the default) or "whole" (the whole silhouette's, what hides it ignored)."""

    size: int = 640
    kind: str | None = None
    style: str | None = None
    people: tuple[int, int] | None = None
    camera: FisheyeCamera | None = None
    images_per_scene: int = 4
    min_visible_fraction: float = 0.15
    min_visible_px: int = 20
    jpeg_quality: int | None = None
    boxes: str = "visible"

    def __post_init__(self) -> None:
        if self.boxes not in BOX_KINDS:
            raise ValueError(f"boxes must be one of {', '.join(BOX_KINDS)}, got {self.boxes!r}")


@dataclass(frozen=True)
class SynthFrame:
    """An encoded frame and its ground truth; `camera` is calibrated at the frame's size."""

    index: int
    jpeg: bytes
    width: int
    height: int
    scene_id: str
    split: str
    camera: FisheyeCamera
    people: list[PersonTruth] = field(default_factory=list)


_scene_cache: dict[tuple[str, int, str, str], Scene] = {}
_background_cache: dict[tuple[str, int], Background] = {}
_static_cache: dict[tuple[str, int, bool], StaticScene] = {}


def _style(config: SynthConfig, scene_index: int) -> str | None:
    if not config.style:
        return None
    styles = config.style.split(",")
    return styles[scene_index % len(styles)]


def _scene(split: str, scene_index: int, config: SynthConfig) -> Scene:
    camera_key = config.camera.model_dump_json() if config.camera is not None else ""
    key = (split, scene_index, f"{config.kind}/{config.style}", camera_key)
    if key not in _scene_cache:
        _scene_cache.clear()
        _background_cache.clear()
        _static_cache.clear()
        _scene_cache[key] = build_scene(split, scene_index, config.kind, config.camera,
                                                 _style(config, scene_index))
    return _scene_cache[key]


def light_direction(scene: Scene, night: bool) -> tuple[float, float, float]:
    """The scene's light direction (unit vector towards the light) by day or by night: fixed per
    scene, so its static objects' shadows are cast once."""
    rng = np.random.default_rng([zlib.crc32(scene.scene_id.encode()), int(night)])
    if scene.kind == "outdoor" and not night:
        elevation = rng.uniform(np.radians(25), np.radians(80))
    else:
        elevation = rng.uniform(np.radians(60), np.radians(89))
    azimuth = rng.uniform(0, 2 * np.pi)
    direction = np.array([np.cos(azimuth) * np.cos(elevation), np.sin(azimuth) * np.cos(elevation),
                          np.sin(elevation)])
    return float(direction[0]), float(direction[1]), float(direction[2])


def sample_lighting(rng: np.random.Generator, scene: Scene, night: bool) -> Lighting:
    """Sun or ceiling light, ambient and shadow softness for one frame."""
    if scene.kind == "outdoor" and not night:
        sun = rng.uniform(2.0, 3.5) * np.array([1.0, 0.96, 0.88])
        ambient = rng.uniform(0.5, 0.9) * np.array([0.8, 0.9, 1.1])
        softness = rng.uniform(0.5, 1.5)
    elif scene.kind == "outdoor":
        sun = rng.uniform(0.6, 1.2) * np.array([1.0, 0.75, 0.45])
        ambient = rng.uniform(0.15, 0.35) * np.array([0.9, 0.85, 0.9])
        softness = rng.uniform(2.0, 5.0)
    else:
        warm = rng.uniform(0.0, 0.2) + (0.25 if night else 0.0)
        sun = rng.uniform(0.3, 0.8) * np.array([1.0, 1.0 - warm * 0.5, 1.0 - warm])
        ambient = rng.uniform(0.6, 1.0) * np.array([1.0, 1.0 - warm * 0.4, 1.0 - warm * 0.8])
        softness = rng.uniform(2.0, 6.0)
    return Lighting(
        direction=light_direction(scene, night),
        color=(float(sun[0]), float(sun[1]), float(sun[2])),
        ambient=(float(ambient[0]), float(ambient[1]), float(ambient[2])),
        shadow_softness=float(softness),
        sky_gain=0.15 if night else 1.6,
    )


def render_frame(seed: int, split: str, index: int, config: SynthConfig) -> SynthFrame:
    """Frame `index` of the data set (seed, split); see the module docstring."""
    return render_frame_with_ids(seed, split, index, config)[0]


def render_frame_with_ids(seed: int, split: str, index: int, config: SynthConfig
                          ) -> tuple[SynthFrame, NDArray[np.int32]]:
    """`render_frame` and the id image (H, W) of the z-buffer (person index, -1 where none); a
    PersonTruth's `person` indexes it."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    scene = _scene(split, index // config.images_per_scene, config)
    camera = scene.camera.scaled_to((config.size, config.size))
    grid = ray_grid(camera)
    bg_key = (scene.scene_id, config.size)
    if bg_key not in _background_cache:
        _background_cache[bg_key] = trace_environment(scene.environment, grid)
    background = _background_cache[bg_key]
    rng = np.random.default_rng([int(seed), SPLITS.index(split), int(index), 7])
    if config.people is None:
        count = sample_count(rng)
    else:
        count = int(rng.integers(config.people[0], config.people[1] + 1))
    specs, extra = place_people(rng, scene, count)
    people = [build_person(spec) for spec in specs]
    groups = [Group(o.primitives) for o in extra]
    groups += [Group(p.primitives, person=i) for i, p in enumerate(people)]
    night = bool(rng.random() < 0.2)
    lighting = sample_lighting(rng, scene, night)
    static_key = (scene.scene_id, config.size, night)
    if static_key not in _static_cache:
        fixed = [Group(o.primitives) for o in scene.objects]
        _static_cache[static_key] = render_static(grid, background, fixed, lighting.direction)
    output = render(grid, _static_cache[static_key], groups, lighting, len(people))
    locations = np.array([p.location_m for p in people]).reshape(-1, 2)
    truths = people_truth(output.person_id, output.unoccluded_px, locations, camera.principal_point,
                          config.min_visible_fraction, config.min_visible_px,
                          output.whole_uv if config.boxes == "whole" else None)
    settings = sample_sensor(rng, night)
    if config.jpeg_quality is not None:
        settings = type(settings)(**{**settings.__dict__, "jpeg_quality": config.jpeg_quality})
    image = develop(output.image, grid, settings, rng)
    frame = SynthFrame(
        index=index,
        jpeg=encode_jpeg(image, settings.jpeg_quality),
        width=config.size,
        height=config.size,
        scene_id=scene.scene_id,
        split=split,
        camera=camera,
        people=truths,
    )
    return frame, output.person_id
