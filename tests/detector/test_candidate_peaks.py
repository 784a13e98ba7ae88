"""Peak cells before the graph's top K: one candidate per blob of a level, so a crowd's weak people
still reach NMS."""

from __future__ import annotations

import torch

from detector.yolox.decode import peak_cells
from detector.yolox.head import CLASSES_START, OBJECTNESS


def _maps(blobs: list[list[tuple[int, int, float]]], size: int = 8) -> list[torch.Tensor]:
    """One (1, 6, size, size) raw map per level with person logits peaking at the blobs' cells
    (each blob: its centre cell and logit, its 8 neighbours 1 lower)."""
    maps = []
    for level in blobs:
        m = torch.full((1, 6, size, size), -8.0)
        m[:, CLASSES_START] = 4.0  # p(person) ~ 1: objectness decides
        for row, col, logit in level:
            m[0, OBJECTNESS, max(row - 1, 0):row + 2, max(col - 1, 0):col + 2] = logit - 1.0
            m[0, OBJECTNESS, row, col] = logit
        maps.append(m)
    return maps


def test_empty_maps_have_only_flat_peaks() -> None:
    # A level without any person is flat: every cell ties with its neighbours and stays (score ~0).
    peaks = peak_cells(_maps([[]]))
    assert peaks.shape == (1, 64) and bool(peaks.all())


def test_one_peak_per_blob_on_each_level() -> None:
    maps = _maps([[(2, 2, 3.0), (5, 6, 1.0)], [(4, 4, 2.0)]])
    peaks = peak_cells(maps).reshape(2, 8, 8)  # levels stacked: 64 cells each
    for level, blobs in enumerate([[(2, 2), (5, 6)], [(4, 4)]]):
        lit = maps[level][0, OBJECTNESS] > -8.0
        found = {(int(r), int(c)) for r, c in torch.nonzero(peaks[level] & lit)}
        assert found == set(blobs)


def test_a_weak_neighbour_two_cells_away_keeps_its_peak() -> None:
    maps = _maps([[(3, 2, 4.0), (3, 5, 0.5)]])
    peaks = peak_cells(maps).reshape(8, 8)
    assert bool(peaks[3, 2]) and bool(peaks[3, 5]) and not bool(peaks[3, 3])
