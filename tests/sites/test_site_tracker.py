"""The site tracker on synthetic trajectories: fusion of overlapping views, hand-over, late frames,
line crossings with DESIGN.md's sign convention, zone dwell, the end of tracks."""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import pytest
from sites_scenes import START, Cam, frames, line_walk

from sites import CountingLine, SiteLayout, SiteObservation, SiteTracker, TrackerConfig, Zone

# Two cameras 6 m apart seeing 4.5 m around their nadirs: views overlap on x in [-1.5, 1.5].
TWO_CAMS = [Cam("cam-a", (-3.0, 0.0), 4.5), Cam("cam-b", (3.0, 0.0), 4.5)]


def _ids_per_person(tracker: SiteTracker, scene: list) -> dict[int, set[str]]:
    ids: dict[int, set[str]] = defaultdict(set)
    for observation, who in scene:
        outcome = tracker.update(observation)
        assert outcome.use == "used"
        for person, track_id in zip(who, outcome.track_ids, strict=True):
            if track_id is not None:
                ids[person].add(track_id)
    return ids


def test_overlapping_views_give_one_track_per_person() -> None:
    # Two people standing still in the overlap, 1.5 m apart: each is seen by both cameras.
    people = [line_walk((0.0, 0.75), (0.0, 0.0)), line_walk((0.0, -0.75), (0.0, 0.0))]
    tracker = SiteTracker("hall")
    ids = _ids_per_person(tracker, list(frames(TWO_CAMS, people, seconds=3.0)))
    assert len(ids[0]) == 1 and len(ids[1]) == 1
    assert ids[0] != ids[1]
    occupancy = tracker.occupancy()
    assert occupancy["count"] == 2
    assert all(person["cameras"] == ["cam-a", "cam-b"] for person in occupancy["people"])
    by_id = {person["track_id"]: person["position_m"] for person in occupancy["people"]}
    np.testing.assert_allclose(by_id[next(iter(ids[0]))], [0.0, 0.75], atol=0.15)


def test_hand_over_keeps_the_id_across_a_gap_between_views() -> None:
    # Views that do not overlap (each sees 2.5 m): a walker at 1 m/s is unseen for 1 s in between.
    cams = [Cam("cam-a", (-3.0, 0.0), 2.5), Cam("cam-b", (3.0, 0.0), 2.5)]
    walker = line_walk((-5.0, 0.3), (1.0, 0.0))
    tracker = SiteTracker("hall")
    ids = _ids_per_person(tracker, list(frames(cams, [walker], seconds=10.0)))
    assert len(ids[0]) == 1
    assert tracker.occupancy()["people"][0]["cameras"] == ["cam-b"]
    assert tracker.ended == 0


def test_a_new_track_is_reported_only_once_confirmed() -> None:
    tracker = SiteTracker("hall", TrackerConfig(min_hits=3))
    outcomes = [tracker.update(SiteObservation.of("cam-a", START + k * 0.1, [[1.0, 1.0]])).track_ids[0]
                for k in range(4)]
    assert outcomes == [None, None, "hall:1", "hall:1"]


def test_a_track_ends_after_the_coast_time() -> None:
    # Reported while coasting as long as it is kept (the report-coast has its own test).
    tracker = SiteTracker("hall", TrackerConfig(max_coast_s=1.0, report_coast_s=1.0))
    for k in range(5):
        tracker.update(SiteObservation.of("cam-a", START + k * 0.1, [[1.0, 1.0]]))
    tracker.update(SiteObservation.of("cam-a", START + 1.3, np.zeros((0, 2))))
    assert tracker.occupancy()["count"] == 1  # coasting, 0.9 s unseen
    tracker.update(SiteObservation.of("cam-a", START + 1.5, np.zeros((0, 2))))
    assert tracker.occupancy()["count"] == 0
    assert tracker.ended == 1


def _play(tracker: SiteTracker, observations: list[SiteObservation]) -> list[str]:
    return [tracker.update(observation).use for observation in observations]


def test_a_late_frame_within_the_window_is_used_as_if_in_order() -> None:
    people = [line_walk((-4.0, 0.5), (1.0, 0.0)), line_walk((4.0, -0.5), (-1.0, 0.0))]
    layout = SiteLayout.of(lines=[CountingLine("door", np.array([0.0, -3.0]), np.array([0.0, 3.0]))])
    in_order = [observation for observation, _ in frames(TWO_CAMS, people, seconds=6.0)]
    shuffled = list(in_order)
    late = shuffled.pop(40)  # 2.0 s, arriving after the frames up to 2.2 s
    shuffled.insert(44, late)
    reference = SiteTracker("hall", TrackerConfig(reorder_window_s=0.5), layout)
    _play(reference, in_order)
    tracker = SiteTracker("hall", TrackerConfig(reorder_window_s=0.5), layout)
    uses = _play(tracker, shuffled)
    assert uses[44] == "used_late" and uses.count("used_late") == 1
    assert tracker.frames.used_late == 1 and tracker.frames.dropped_late == 0
    assert tracker.occupancy() == reference.occupancy()
    assert tracker.occupancy()["lines"]["door"] == {"in": 1, "out": 1}


def test_a_frame_later_than_the_window_is_dropped_and_counted() -> None:
    tracker = SiteTracker("hall", TrackerConfig(reorder_window_s=0.5))
    for k in range(10):
        tracker.update(SiteObservation.of("cam-a", START + k * 0.1, [[1.0, 1.0]]))
    before = tracker.occupancy()
    outcome = tracker.update(SiteObservation.of("cam-b", START + 0.2, [[5.0, 5.0]]))
    assert outcome.use == "dropped_late" and outcome.track_ids == (None,)
    assert tracker.frames.dropped_late == 1
    assert tracker.occupancy() == before


@pytest.mark.parametrize(("velocity", "expected"), [
    ((1.0, 0.0), {"in": 1, "out": 0}),   # from x < 0 (left of the line looking up +y) to x > 0
    ((-1.0, 0.0), {"in": 0, "out": 1}),
])
def test_line_crossings_follow_the_sign_convention(velocity: tuple[float, float],
                                                   expected: dict[str, int]) -> None:
    # The line runs from (0, -3) to (0, 3): looking from from_m to to_m (up +y), -x is the left side.
    start = (-3.0 * velocity[0], 0.5)
    layout = SiteLayout.of(lines=[CountingLine("door", np.array([0.0, -3.0]), np.array([0.0, 3.0]))])
    tracker = SiteTracker("hall", layout=layout)
    _ids_per_person(tracker, list(frames(TWO_CAMS, [line_walk(start, velocity)], seconds=6.0)))
    assert tracker.occupancy()["lines"] == {"door": expected}


def test_a_person_standing_on_a_line_is_not_counted_again_and_again() -> None:
    layout = SiteLayout.of(lines=[CountingLine("door", np.array([0.0, -3.0]), np.array([0.0, 3.0]))])
    tracker = SiteTracker("hall", layout=layout)
    still = line_walk((0.0, 0.5), (0.0, 0.0))
    _ids_per_person(tracker, list(frames(TWO_CAMS, [still], seconds=10.0, noise_base_m=0.08)))
    assert tracker.occupancy()["lines"] == {"door": {"in": 0, "out": 0}}


def _lingering_tallies(config: TrackerConfig) -> dict[str, int]:
    """A person who walks onto the door line, lingers on it for 10 s (their positions jittering
    0.15 m either side of it), then walks on through: one crossing."""
    layout = SiteLayout.of(lines=[CountingLine("door", np.array([0.0, -3.0]), np.array([0.0, 3.0]))])
    tracker = SiteTracker("hall", config, layout)
    xs = [-1.0 + 0.1 * k for k in range(10)]
    xs += list(np.random.default_rng(1).normal(0.0, 0.15, 100))
    xs += [0.1 * k for k in range(25)]
    for k, x in enumerate(xs):
        tracker.update(SiteObservation.of("cam-a", START + k * 0.1, [[x, 0.5]]))
    return dict(tracker.occupancy()["lines"]["door"])


def test_a_person_lingering_on_a_line_counts_once() -> None:
    assert _lingering_tallies(TrackerConfig()) == {"in": 1, "out": 0}
    # Without the hold in time, the same walk counts every sway.
    swaying = _lingering_tallies(TrackerConfig(line_hold_s=0.0))
    assert swaying["in"] > 1 and swaying["out"] > 0


def test_a_track_ending_just_past_a_line_counts_its_crossing() -> None:
    layout = SiteLayout.of(lines=[CountingLine("door", np.array([0.0, -3.0]), np.array([0.0, 3.0]))])
    tracker = SiteTracker("hall", TrackerConfig(line_hold_s=1.0), layout)
    for k in range(8):  # walks from -1.0 to 0.4 m, then is seen no more
        tracker.update(SiteObservation.of("cam-a", START + k * 0.2, [[-1.0 + 0.2 * k, 0.5]]))
    assert tracker.occupancy()["lines"]["door"] == {"in": 0, "out": 0}  # held, not yet counted
    tracker.update(SiteObservation.of("cam-a", START + 5.0, np.zeros((0, 2))))
    assert tracker.tracks == []
    assert tracker.occupancy()["lines"]["door"] == {"in": 1, "out": 0}


def test_zone_counts_and_dwell_per_track() -> None:
    square = Zone("entrance", np.array([[-4.0, -1.0], [-2.0, -1.0], [-2.0, 1.0], [-4.0, 1.0]]))
    tracker = SiteTracker("hall", layout=SiteLayout.of(zones=[square]))
    stays = line_walk((-3.0, 0.0), (0.0, 0.0), t0=0.0, t1=5.0)   # 5 s in the zone, then gone
    passes = line_walk((-3.0, 3.0), (1.0, 0.0))                 # never in it
    for observation, _ in frames(TWO_CAMS, [stays, passes], seconds=4.0):
        tracker.update(observation)
    occupancy = tracker.occupancy()
    assert occupancy["zones"] == {"entrance": {"count": 1}}
    dwell = {person["track_id"]: person["dwell_s"] for person in occupancy["people"]}
    inside = [d["entrance"] for d in dwell.values() if "entrance" in d]
    assert len(inside) == 1
    # Dwell counts from the first frame (0.0 s), the tentative part included, to the last (3.9 s).
    assert inside[0] == pytest.approx(3.9, abs=0.11)


def test_removing_a_camera_ends_the_tracks_only_it_saw() -> None:
    people = [line_walk((-3.0, 0.0), (0.0, 0.0)), line_walk((0.0, 0.0), (0.0, 0.0))]
    tracker = SiteTracker("hall")
    for observation, _ in frames(TWO_CAMS, people, seconds=1.0):
        tracker.update(observation)
    assert tracker.occupancy()["count"] == 2
    assert tracker.remove_camera("cam-a") == 1  # the person only cam-a saw
    remaining = tracker.occupancy()["people"]
    assert len(remaining) == 1 and remaining[0]["cameras"] == ["cam-b"]


def test_nan_positions_join_no_track() -> None:
    tracker = SiteTracker("hall", TrackerConfig(min_hits=1))
    observation = SiteObservation.of("cam-a", START, [[np.nan, np.nan], [1.0, 1.0]], [np.nan, 1.0])
    outcome = tracker.update(observation)
    assert outcome.track_ids == (None, "hall:1")


@pytest.mark.parametrize("bad", [
    {"positions_m": np.zeros((2, 2)), "distance_m": np.zeros(1), "scores": np.zeros(2)},
    {"positions_m": np.zeros((1, 2)), "distance_m": np.zeros(1), "scores": np.zeros(3)},
])
def test_observations_with_mismatched_arrays_are_refused(bad: dict[str, np.ndarray]) -> None:
    with pytest.raises(ValueError, match="SiteObservation"):
        SiteObservation("cam-a", START, **bad)


def test_an_observation_needs_a_finite_capture_time() -> None:
    with pytest.raises(ValueError, match="capture_time"):
        SiteObservation.of("cam-a", float("nan"), np.zeros((0, 2)))


def test_many_late_frames_give_the_tracks_of_capture_order() -> None:
    # Every tenth frame swapped behind the next step's frames: the tracker must end exactly where
    # the same frames in capture order (ties in arrival order) lead, line tallies included.
    people = [line_walk((-4.0, y), (1.0, 0.2)) for y in (-1.5, 0.0, 1.5)]
    people += [line_walk((4.0, y), (-0.8, 0.0)) for y in (-1.0, 1.0)]
    layout = SiteLayout.of(lines=[CountingLine("door", np.array([0.0, -3.0]), np.array([0.0, 3.0]))])
    frames_in_order = [observation for observation, _ in frames(TWO_CAMS, people, seconds=8.0)]
    arrival = list(range(len(frames_in_order)))
    for index in range(0, len(arrival) - 2, 10):
        arrival[index], arrival[index + 2] = arrival[index + 2], arrival[index]
    by_capture = sorted(arrival, key=lambda i: (frames_in_order[i].capture_time, arrival.index(i)))
    reference = SiteTracker("hall", layout=layout)
    _play(reference, [frames_in_order[i] for i in by_capture])
    tracker = SiteTracker("hall", layout=layout)
    _play(tracker, [frames_in_order[i] for i in arrival])
    assert tracker.frames.used_late > 10
    assert tracker.occupancy() == reference.occupancy()
    assert tracker.occupancy()["count"] == 5


# ----- a real detector's output: doubles, weak detections, people leaving, late confirmation


def test_one_person_twice_in_one_frame_is_one_track() -> None:
    # Each frame of cam-a sees the walker twice, 0.35 m apart along the radius (3 m out): one person.
    tracker = SiteTracker("hall")
    ids = set()
    for k in range(10):
        x = 3.0 + 0.1 * k
        outcome = tracker.update(SiteObservation.of("cam-a", START + k * 0.2, [[x, 0.0], [x + 0.35, 0.0]],
                                                    [x, x + 0.35], [0.9, 0.6]))
        assert outcome.track_ids[0] == outcome.track_ids[1]
        ids.add(outcome.track_ids[0])
    assert ids - {None} == {"hall:1"}
    assert tracker.occupancy()["count"] == 1


def test_weak_detections_never_start_a_track() -> None:
    config = TrackerConfig(high_score=0.8, low_score=0.3)
    tracker = SiteTracker("hall", config)
    for k in range(20):
        tracker.update(SiteObservation.of("cam-a", START + k * 0.2, [[1.0, 1.0]], [1.0], [0.6]))
    assert tracker.occupancy()["count"] == 0
    assert tracker.tracks == []


def test_weak_detections_extend_a_confirmed_track() -> None:
    # Confident while the track starts, then weak (above low_score) for 4 s: the same track all along,
    # following the walker; below low_score the detections are not used at all.
    config = TrackerConfig(high_score=0.8, low_score=0.3, max_coast_s=1.0)
    tracker = SiteTracker("hall", config)
    ids = []
    for k in range(25):
        score = 0.9 if k < 3 else 0.5
        xy = [[0.2 * k, 0.0], [5.0, 5.0]]  # the walker, and a weaker stray spot
        outcome = tracker.update(SiteObservation.of("cam-a", START + k * 0.2, xy, [1.0, 1.0], [score, 0.2]))
        ids.append(outcome.track_ids[0])
        assert outcome.track_ids[1] is None
    assert set(ids[1:]) == {"hall:1"}
    people = tracker.occupancy()["people"]
    assert len(people) == 1
    np.testing.assert_allclose(people[0]["position_m"], [4.8, 0.0], atol=0.1)


def test_a_coasting_track_is_reported_briefly_and_kept_longer() -> None:
    config = TrackerConfig(report_coast_s=0.5, max_coast_s=2.0)
    tracker = SiteTracker("hall", config)
    for k in range(5):
        tracker.update(SiteObservation.of("cam-a", START + k * 0.2, [[1.0, 1.0]]))
    last = START + 0.8
    tracker.update(SiteObservation.of("cam-a", last + 0.4, np.zeros((0, 2))))
    assert tracker.occupancy()["count"] == 1  # unseen 0.4 s: still reported
    tracker.update(SiteObservation.of("cam-a", last + 0.8, np.zeros((0, 2))))
    assert tracker.occupancy()["count"] == 0  # unseen 0.8 s: not reported...
    assert [track.number for track in tracker.tracks] == [1]  # ...but kept
    outcome = tracker.update(SiteObservation.of("cam-a", last + 1.4, [[1.0, 1.0]]))
    assert outcome.track_ids == ("hall:1",)  # and the person re-joins it
    assert tracker.occupancy()["count"] == 1
    assert tracker.ended == 0


def test_a_crossing_before_confirmation_is_counted_once_confirmed() -> None:
    # The walker crosses the door between the first and second frames; the track is confirmed only at
    # the fifth frame, well past the line: one `in`, counted once.
    layout = SiteLayout.of(lines=[CountingLine("door", np.array([0.0, -3.0]), np.array([0.0, 3.0]))])
    tracker = SiteTracker("hall", TrackerConfig(min_hits=5), layout)
    tallies = []
    for k in range(12):
        tracker.update(SiteObservation.of("cam-a", START + k * 0.2, [[-0.3 + 0.3 * k, 0.5]]))
        tallies.append(tracker.occupancy()["lines"]["door"]["in"])
    assert tallies == [0] * 4 + [1] * 8
    assert tracker.occupancy()["lines"] == {"door": {"in": 1, "out": 0}}


def test_a_crossing_of_a_track_never_confirmed_is_not_counted() -> None:
    layout = SiteLayout.of(lines=[CountingLine("door", np.array([0.0, -3.0]), np.array([0.0, 3.0]))])
    tracker = SiteTracker("hall", TrackerConfig(min_hits=5), layout)
    for k in range(4):  # four frames, then gone: tentative to the end
        tracker.update(SiteObservation.of("cam-a", START + k * 0.2, [[-0.3 + 0.3 * k, 0.5]]))
    for k in range(4, 15):
        tracker.update(SiteObservation.of("cam-a", START + k * 0.2, np.zeros((0, 2))))
    assert tracker.occupancy()["lines"] == {"door": {"in": 0, "out": 0}}
    assert tracker.tracks == []
