"""One step of a synthetic sequence seen by one camera of a site: people, render, ground truth, JPEG.

Everything random comes from the sequence's seed: the world's colours and furniture
(`site_world`), everyone's route (`walkers`), each person's looks (seeded from seed and track id),
the light (one for the whole sequence), each camera's sensor (one per camera) and each frame's
noise (seeded from seed, camera and step). A frame is therefore the same whichever process renders
it and in whatever order, and every camera of a step sees the same people in the same places.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from detector.data.body import PersonSpec, build_person
from detector.data.crowd import sample_person
from detector.data.environment import Background, trace_environment
from detector.data.ground_truth import PersonTruth, people_truth
from detector.data.rays import RayGrid, posed_grid, ray_grid
from detector.data.render import Group, Lighting, StaticScene, render, render_static
from detector.data.sensor import SensorSettings, develop, encode_jpeg, sample_sensor
from detector.data.site_world import SitePlan, SiteWorld, build_site_world
from detector.data.synth import sample_lighting
from detector.data.walkers import Walker, sample_walkers
from fisheye import FisheyeCamera

FloatArray = NDArray[np.float64]

EPOCH_S = 1764590400.0  # 2025-12-01T12:00:00Z: the capture time of a sequence's first step


@dataclass(frozen=True)
class SequenceConfig:
    """What to render: `steps` steps at `fps` of the site `plan` from `seed`, frames `size` px square,
    `people` (None: 18 per minute, at least 10) and the ignore rule of `SynthConfig`."""

    plan: SitePlan
    steps: int
    fps: float = 5.0
    seed: int = 0
    size: int = 1024
    people: int | None = None
    min_visible_fraction: float = 0.15
    min_visible_px: int = 20

    def capture_time(self, step: int) -> float:
        return round(EPOCH_S + step / self.fps, 6)


@dataclass(frozen=True)
class SequenceTruth:
    """A person in one camera's frame: the frame's truth plus `track_id` and `site_location_m`."""

    track_id: int
    site_location_m: tuple[float, float]
    truth: PersonTruth


@dataclass(frozen=True)
class SequenceFrame:
    """An encoded frame of `camera` (calibrated at the frame's size) at `step`, and its truth."""

    step: int
    capture_time: float
    camera: FisheyeCamera
    jpeg: bytes
    width: int
    height: int
    people: list[SequenceTruth] = field(default_factory=list)


@dataclass
class _CameraView:
    grid: RayGrid
    background: Background
    static: StaticScene
    sensor: SensorSettings


class SequenceRenderer:
    """Renders the frames of one sequence; builds the world, routes and camera views once."""

    def __init__(self, config: SequenceConfig) -> None:
        self.config = config
        self._views: dict[int, _CameraView] = {}

    @cached_property
    def world(self) -> SiteWorld:
        return build_site_world(self.config.plan, self.config.seed)

    @cached_property
    def walkers(self) -> list[Walker]:
        c = self.config
        return sample_walkers(self.world, c.steps, c.fps, c.seed, c.people)

    @cached_property
    def looks(self) -> dict[int, PersonSpec]:
        """Each person's body and clothes, drawn from (seed, track id)."""
        out = {}
        for walker in self.walkers:
            rng = np.random.default_rng([int(self.config.seed), walker.track_id, 77])
            spec = sample_person(rng, 0.0, 0.0, 0.0, "walking")
            # People passing through carry a bag or nothing (no box or phone held out for a minute).
            out[walker.track_id] = replace(spec, carried="none" if rng.random() < 0.5 else "bag")
        return out

    @cached_property
    def lighting(self) -> Lighting:
        return sample_lighting(np.random.default_rng([int(self.config.seed), 5]), self.world.scene, False)

    def cameras(self) -> list[FisheyeCamera]:
        """The plan's cameras calibrated at the frame size."""
        size = self.config.size
        return [c.scaled_to((size, size)) for c in self.config.plan.cameras]

    def _view(self, index: int) -> _CameraView:
        if index not in self._views:
            camera = self.cameras()[index]
            pose = camera.site_pose
            assert pose is not None  # SitePlan checks it
            grid = posed_grid(ray_grid(camera), (pose.x_m, pose.y_m), np.radians(pose.yaw_deg))
            background = trace_environment(self.world.scene.environment, grid)
            fixed = [Group(o.primitives) for o in self.world.scene.objects]
            static = render_static(grid, background, fixed, self.lighting.direction)
            sensor = sample_sensor(np.random.default_rng([int(self.config.seed), index, 11]), False)
            self._views[index] = _CameraView(grid, background, static, sensor)
        return self._views[index]

    def specs(self, step: int) -> list[tuple[int, PersonSpec]]:
        """(track id, spec) of everyone inside the site at `step`."""
        out = []
        for walker in self.walkers:
            if not walker.present(step):
                continue
            state = walker.state(step)
            spec = replace(self.looks[walker.track_id], position_m=state.position_m,
                           heading_rad=state.heading_rad, pose="walking" if state.walking else "standing",
                           phase_rad=state.phase_rad)
            out.append((walker.track_id, spec))
        return out

    def render(self, step: int, camera_index: int) -> SequenceFrame:
        """The frame of camera `camera_index` at `step`."""
        c = self.config
        view = self._view(camera_index)
        camera = view.grid.camera
        present = self.specs(step)
        people = [build_person(spec) for _, spec in present]
        groups = [Group(p.primitives, person=i) for i, p in enumerate(people)]
        output = render(view.grid, view.static, groups, self.lighting, len(people))
        site_xy = np.array([p.location_m for p in people]).reshape(-1, 2)
        pose = camera.site_pose
        assert pose is not None
        local_xy = pose.site_to_floor(site_xy) if len(site_xy) else site_xy
        truths = people_truth(output.person_id, output.unoccluded_px, local_xy, camera.principal_point,
                              c.min_visible_fraction, c.min_visible_px)
        rng = np.random.default_rng([int(c.seed), camera_index, step, 13])
        image = develop(output.image, view.grid, view.sensor, rng)
        return SequenceFrame(
            step=step,
            capture_time=c.capture_time(step),
            camera=camera,
            jpeg=encode_jpeg(image, view.sensor.jpeg_quality),
            width=c.size,
            height=c.size,
            people=[SequenceTruth(present[t.person][0],
                                  (float(site_xy[t.person, 0]), float(site_xy[t.person, 1])), t)
                    for t in truths],
        )
