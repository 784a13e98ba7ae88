"""Scores of reported site tracks: line crossings, zones, MOTA/IDF1, duplicates, hidden people."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from evaluation.sequence_data import Sequence, SequenceFrame, SequencePerson, SequenceStep
from evaluation.track_scoring import (
    Reported,
    inside_polygon,
    line_crossings,
    score_detections,
    score_sequence,
    true_line_counts,
)

# A door line along the y axis at x = 1: looking from (1, -1) to (1, 1) the left side is x < 1.
LINE = {"from_m": [1.0, -1.0], "to_m": [1.0, 1.0]}
ZONE = {"polygon_m": [[0.0, -2.0], [2.0, -2.0], [2.0, 2.0], [0.0, 2.0]]}


@pytest.mark.parametrize(("before", "after", "expected"), [
    ([], [], []),
    ([[0.0, 0.0]], [[2.0, 0.0]], [1]),             # left to right: in
    ([[2.0, 0.5]], [[0.0, 0.5]], [-1]),            # right to left: out
    ([[0.0, 0.0]], [[0.5, 0.0]], [0]),             # stays on the left
    ([[0.0, 3.0]], [[2.0, 3.0]], [0]),             # passes beyond the line's end
    ([[0.0, -1.5], [2.0, 0.9]], [[2.0, 0.5], [0.5, 0.9]], [1, -1]),  # a diagonal in, an out
])
def test_line_crossings_follow_the_sign_convention(before: list[list[float]], after: list[list[float]],
                                                   expected: list[int]) -> None:
    signs = line_crossings(np.array(before).reshape(-1, 2), np.array(after).reshape(-1, 2),
                           np.array(LINE["from_m"]), np.array(LINE["to_m"]))
    assert signs.tolist() == expected


@pytest.mark.parametrize(("points", "expected"), [
    ([], []),
    ([[1.0, 0.0], [3.0, 0.0], [1.0, 2.5], [-0.1, 1.0]], [True, False, False, False]),
])
def test_inside_polygon(points: list[list[float]], expected: list[bool]) -> None:
    inside = inside_polygon(np.array(points).reshape(-1, 2), np.array(ZONE["polygon_m"]))
    assert inside.tolist() == expected


def _sequence(paths: dict[int, list[tuple[float, float] | None]], hidden: set[tuple[int, int]] = frozenset()
              ) -> Sequence:
    """Steps of the given true paths (None: outside the site); (track, step) in `hidden` is inside
    but shown by no camera."""
    steps = []
    for k in range(len(next(iter(paths.values())))):
        present = {t: xy for t, path in paths.items() if (xy := path[k]) is not None}
        visible = frozenset(t for t in present if (t, k) not in hidden)
        steps.append(SequenceStep(1000.0 + k / 5, [], present, visible))
    return Sequence("s", [], {"door-zone": ZONE}, {"door": LINE}, steps)


def _reported(people: list[dict[str, tuple[float, float]]], sequence: Sequence) -> Reported:
    reported = Reported()
    for step, now in zip(sequence.steps, people, strict=True):
        xy = np.array(list(now.values())).reshape(-1, 2)
        count = int(inside_polygon(xy, np.array(ZONE["polygon_m"])).sum())
        reported.add({"people": [{"track_id": h, "position_m": list(p)} for h, p in now.items()],
                      "zones": {"door-zone": {"count": count}}, "lines": {"door": {"in": 0, "out": 0}},
                      "time": step.capture_time})
    return reported


def _truth_report() -> list[dict[str, tuple[float, float]]]:
    """Both true people at every step they are in, as tracks s:1 and s:2."""
    steps = range(len(WALK_IN))
    return [{f"s:{t}": xy for t, xy in ((1, WALK_IN[k]), (2, STAND[k])) if xy is not None} for k in steps]


WALK_IN = [None, (0.2, 0.0), (0.6, 0.0), (1.2, 0.0), (1.6, 0.0), (2.4, 0.0)]
STAND = [(5.0, 5.0)] * 6


def test_a_perfect_report_scores_one_and_line_counts_match() -> None:
    sequence = _sequence({1: WALK_IN, 2: STAND})
    assert true_line_counts(sequence) == {"door": {"in": 1, "out": 0}}
    people = _truth_report()
    reported = _reported(people, sequence)
    reported.lines_after = {"door": {"in": 1, "out": 0}}
    figures = score_sequence(sequence, reported)
    assert figures["mota"] == pytest.approx(1.0) and figures["idf1"] == pytest.approx(1.0)
    assert (figures["id_switches"], figures["duplicates"], figures["false_positives"]) == (0, 0, 0)
    assert figures["lines"]["door"]["in"] == {"true": 1, "reported": 1, "relative_error": 0.0}
    assert figures["lines"]["door"]["out"]["relative_error"] is None
    assert figures["zones"]["door-zone"]["count_mae"] == 0.0


def test_a_person_reported_twice_is_a_duplicate_and_a_lost_line_count_is_an_error() -> None:
    sequence = _sequence({1: WALK_IN, 2: STAND})
    people = _truth_report()
    people[3]["s:9"] = (1.5, 0.3)  # a second track 0.42 m from person 1, as an unfused overlap gives
    figures = score_sequence(sequence, _reported(people, sequence))
    assert figures["duplicates"] == 1 and figures["false_positives"] == 1
    assert figures["duplicate_rate"] == pytest.approx(1 / (5 + 6 + 1))
    assert figures["lines"]["door"]["in"]["relative_error"] == -1.0
    assert figures["line_error_max"] == 1.0
    assert figures["zones"]["door-zone"]["count_mae"] == pytest.approx(1 / 6)


def test_a_swapped_id_is_a_switch_and_a_far_report_is_a_miss_and_a_false_positive() -> None:
    sequence = _sequence({1: WALK_IN, 2: STAND})
    people = [{("s:1" if k < 4 else "s:7"): WALK_IN[k], "s:2": STAND[k]} for k in range(1, 6)]
    people.insert(0, {"s:2": (6.0, 5.0)})  # 1 m off: outside the 0.75 m gate
    figures = score_sequence(sequence, _reported(people, sequence))
    assert figures["id_switches"] == 1
    assert (figures["misses"], figures["false_positives"], figures["duplicates"]) == (1, 1, 0)
    assert figures["mota"] == pytest.approx(1 - (1 + 1 + 1) / 11)


def test_a_person_hidden_from_every_camera_counts_neither_way() -> None:
    sequence = _sequence({1: WALK_IN, 2: STAND}, hidden={(2, 2), (2, 3)})
    people = _truth_report()
    unseen = [dict(p) for p in people]
    for k in (2, 3):
        del unseen[k]["s:2"]
    for report in (people, unseen):  # a tracker may keep or drop a person nobody sees
        figures = score_sequence(sequence, _reported(report, sequence))
        assert figures["mota"] == pytest.approx(1.0) and figures["true_people_steps"] == 9


def test_the_report_must_cover_every_step(tmp_path: Path) -> None:
    sequence = _sequence({1: WALK_IN})
    with pytest.raises(ValueError, match="5 occupancy answers for 6 steps"):
        score_sequence(sequence, _reported([{}] * 5, _sequence({1: WALK_IN[:5]})))


def test_detections_per_frame_count_second_detections_and_camera_spread() -> None:
    person = SequencePerson(1, (1.0, 0.0), 2.0, False)
    hidden = SequencePerson(2, (4.0, 0.0), 2.0, True)
    frames = [SequenceFrame("a", Path("a.jpg"), [person, hidden]),
              SequenceFrame("b", Path("b.jpg"), [person])]
    sequence = Sequence("s", [], {}, {}, [SequenceStep(1000.0, frames, {1: (1.0, 0.0), 2: (4.0, 0.0)},
                                                      frozenset({1}))])
    reported = Reported(detections=[
        (0, "a", [(1.1, 0.0), (1.4, 0.2), (4.0, 0.0), (9.0, 9.0)]),  # found, again, a hidden one, nobody
        (0, "b", [(0.8, 0.1)]),
    ])
    figures = score_detections(sequence, reported)
    assert figures is not None
    assert (figures["frames"], figures["recall"], figures["precision"]) == (2, 1.0, 2 / 5)
    assert figures["extra_near_a_person_per_frame"] == 0.5 and figures["elsewhere_per_frame"] == 1.0
    assert figures["camera_spread_m"]["max"] == pytest.approx(np.hypot(0.3, 0.1))
    assert score_detections(sequence, Reported()) is None
