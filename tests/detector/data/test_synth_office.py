"""Open-plan office scenes: drawn only when asked for, desks that face across screens, people who
mostly sit at them."""

import numpy as np
import pytest

from detector.data.crowd import place_people
from detector.data.scenes import INDOOR_STYLES, OUTDOOR_STYLES, REQUESTED_STYLES, STYLES, build_scene
from detector.data.synth import SynthConfig, render_frame


def test_the_random_draw_never_picks_a_requested_style() -> None:
    drawn = {build_scene(split, i).style for split in ("seen", "unseen") for i in range(120)}
    assert drawn <= set(INDOOR_STYLES + OUTDOOR_STYLES)
    assert "office" in REQUESTED_STYLES and "office" in STYLES


def test_asking_for_an_office_leaves_other_scenes_unchanged() -> None:
    # The office's random draws happen inside its own builder: the scene of any other style at the
    # same index is the same before and after an office was built.
    before = build_scene("seen", 5, style="library")
    build_scene("seen", 5, style="office")
    after = build_scene("seen", 5, style="library")
    assert before.scene_id == after.scene_id
    assert [o.footprint for o in before.objects] == [o.footprint for o in after.objects]


@pytest.mark.parametrize("split,index", [("seen", 0), ("seen", 3), ("unseen", 1)])
def test_office_desks_face_across_their_screen_with_a_chair_each(split: str, index: int) -> None:
    scene = build_scene(split, index, style="office")
    assert scene.kind == "indoor" and scene.style == "office"
    chairs = [o for o in scene.objects if o.seats]
    assert len(chairs) >= 8, "an open-plan office has rows of workstations"
    lens = np.array([0.0, 0.0, scene.camera.altitude_m])
    for o in scene.objects:
        for p in o.primitives:
            assert np.linalg.norm(p.center - lens) > p.radius_m + 0.1, "nothing solid at the lens"
    # Every seat looks towards a desk's monitors: 0.3-1.2 m ahead of the seat there is desk, not aisle.
    desks = [o for o in scene.objects if len(o.primitives) >= 7 and not o.seats]
    desk_xy = np.array([o.footprint[:2] for o in desks])
    ahead = 0
    for seat in (s for o in chairs for s in o.seats):
        facing = np.array([np.cos(seat.yaw_rad), np.sin(seat.yaw_rad)])
        nearest = desk_xy[np.argmin(np.hypot(*(desk_xy - [seat.x, seat.y]).T))]
        ahead += float(facing @ (nearest - [seat.x, seat.y])) > 0
    assert ahead >= 0.7 * len(chairs), f"{ahead} of {len(chairs)} seats face their desk"


def test_most_people_in_an_office_sit_and_other_scenes_keep_their_share() -> None:
    def sitting_share(style: str) -> float:
        poses = []
        for index in range(4):
            scene = build_scene("seen", index, style=style)
            specs, _ = place_people(np.random.default_rng(index), scene, 30)
            poses += [s.pose for s in specs]
        return poses.count("sitting") / len(poses)

    assert sitting_share("office") > 0.6
    assert sitting_share("classroom") < 0.45


def test_an_office_frame_renders_with_its_people_boxed() -> None:
    frame = render_frame(11, "seen", 0, SynthConfig(size=320, style="office", people=(12, 20)))
    assert frame.scene_id == "indoor-office-s0000"
    assert len(frame.people) >= 6
