"""A tracker's state through JSON and back: the rebuilt tracker answers every later frame exactly as
the original does (what a `fishloc sites` worker that takes a site over relies on)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sites_scenes import START, Cam, frames, line_walk

from sites import CountingLine, SiteLayout, SiteObservation, SiteTracker, TrackerConfig, Zone
from sites.snapshot import observation_from_json, observation_to_json, tracker_from_state, tracker_to_state

TWO_CAMS = [Cam("cam-a", (-3.0, 0.0), 4.5), Cam("cam-b", (3.0, 0.0), 4.5)]
LAYOUT = SiteLayout.of(zones=[Zone("middle", [[-1, -2], [1, -2], [1, 2], [-1, 2]])],
                       lines=[CountingLine("door", [0, -3], [0, 3])])


def _scene() -> list[SiteObservation]:
    people = [line_walk((-4.0, 0.5), (1.2, 0.0)), line_walk((4.0, -0.5), (-1.0, 0.1)),
              line_walk((0.0, 1.5), (0.0, 0.0))]
    return [observation for observation, _ in frames(TWO_CAMS, people, seconds=6.0)]


@pytest.mark.parametrize("cut", [0, 1, 17, 60, 119])
def test_a_tracker_rebuilt_from_its_state_answers_as_the_original(cut: int) -> None:
    scene = _scene()
    config = TrackerConfig()
    original = SiteTracker("hall", config, LAYOUT)
    for observation in scene[:cut]:
        original.update(observation)
    state = json.loads(json.dumps(tracker_to_state(original)))  # through JSON text, as in Redis
    rebuilt = tracker_from_state(state, config, LAYOUT)
    assert rebuilt.occupancy() == original.occupancy()
    # A late frame too: both replay their reordering windows the same way.
    late = [scene[cut - 1]] if cut > 2 else []
    for observation in [*scene[cut:], *late]:
        a, b = original.update(observation), rebuilt.update(observation)
        assert a == b
    assert rebuilt.occupancy() == original.occupancy()
    assert rebuilt.frames == original.frames and rebuilt.ended == original.ended
    assert original.occupancy()["lines"]["door"]["in"] + original.occupancy()["lines"]["door"]["out"] >= 1


def test_observations_round_trip_with_missing_floor_points() -> None:
    for observation in [SiteObservation.of("cam-a", START, np.zeros((0, 2))),
                        SiteObservation.of("cam-b", START + 0.1, [[1.0, 2.0], [np.nan, np.nan]],
                                           [0.5, np.nan], [0.9, 0.4])]:
        back = observation_from_json(observation_to_json(observation))
        assert back.camera_id == observation.camera_id and back.capture_time == observation.capture_time
        np.testing.assert_array_equal(back.positions_m, observation.positions_m)
        np.testing.assert_array_equal(back.distance_m, observation.distance_m)
        np.testing.assert_array_equal(back.scores, observation.scores)


def test_a_state_of_another_version_is_refused() -> None:
    state = tracker_to_state(SiteTracker("hall"))
    with pytest.raises(ValueError, match="version"):
        tracker_from_state({**state, "version": 99}, TrackerConfig(), SiteLayout())
