"""The prompt's numbers against each candidate's depth and speed (model.referent.compare)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from model.nets.text import tokenize_with_numbers
from model.referent.candidates import (
    DEPTH_COLUMN,
    DEPTH_SCALE,
    GEOMETRY_FEATURES,
    RADAR_EVIDENCE,
    RADAR_MEDIAN_VC,
    RADAR_SLOPE_X,
    SPEED_SCALE,
)
from model.referent.compare import (
    COMPARE_FEATURES,
    PER_NUMBER,
    SPEED_UNITS,
    candidate_speed,
    compare_features,
    prompt_numbers,
)
from model.referent.stage import geometry_width
from model.referent.subsets import SUBSET_FEATURES
from tests.model.referent.stage_helpers import answers_without


def _numbers(*texts: str) -> tuple[torch.Tensor, torch.Tensor]:
    rows = [torch.from_numpy(tokenize_with_numbers(t, 30)[1]).float() for t in texts]
    length = max(len(r) for r in rows) + 2  # some padding at the end of every row
    numbers = torch.zeros(len(rows), length, rows[0].shape[1])
    padding = torch.ones(len(rows), length, dtype=torch.bool)
    for i, r in enumerate(rows):
        numbers[i, : len(r)] = r
        padding[i, : len(r)] = False
    return numbers, padding


def test_prompt_numbers_reads_each_number_once_in_order():
    numbers, padding = _numbers(
        "cyclists faster than 50 km/h",
        "cars between 20 and 35 m ahead",
        "a pedestrian about twenty five metres away",
        "the nearest car",
    )
    values, present = prompt_numbers(numbers, padding)
    assert values.tolist() == [[50.0, 0.0], [20.0, 35.0], [25.0, 0.0], [0.0, 0.0]]
    assert present.tolist() == [[1.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]]
    numbers[0, -1] = numbers[0, 3]  # a number under the padding is no number
    assert prompt_numbers(numbers, padding)[1][0].tolist() == [1.0, 0.0]


def _candidates(depths: list[float], speeds: list[float], crossing: list[float]):
    k = len(depths)
    geometry = torch.zeros(1, k, GEOMETRY_FEATURES)
    geometry[0, :, DEPTH_COLUMN] = torch.tensor(depths) / DEPTH_SCALE
    radar = torch.zeros(1, k, 6 + RADAR_EVIDENCE)  # 6 pooled channels, then the evidence
    radar[0, :, 6 + RADAR_MEDIAN_VC] = -torch.tensor(speeds) / SPEED_SCALE
    radar[0, :, 6 + RADAR_SLOPE_X] = torch.tensor(crossing)
    return geometry, radar


def test_speeds_compare_in_each_unit_and_depths_in_metres():
    geometry, radar = _candidates([12.0, 45.0], [7.0, 20.0], [0.0, 0.0])
    assert candidate_speed(radar, geometry)[0].tolist() == pytest.approx([7.0, 20.0])
    numbers, padding = _numbers("cyclists faster than 50 km/h")
    f = compare_features(geometry, radar, numbers, padding)
    assert f.shape == (1, 2, COMPARE_FEATURES)
    first = f[0, :, :PER_NUMBER]
    kmh = 2 + 2 * SPEED_UNITS.index(1.0 / 3.6)
    # 50 km/h = 13.9 m/s: the 7 m/s candidate is below it, the 20 m/s one above.
    assert first[0, kmh] < 0.01 and first[1, kmh] > 0.99
    # Read as 50 m/s, both are slower; read as a depth, 45 m is near 50 and 12 m is not.
    assert first[:, 2].max() < 0.01
    assert first[1, 1] > first[0, 1] and first[0, 0] < 0.01
    assert first[:, -1].tolist() == [1.0, 1.0] and not f[0, :, PER_NUMBER:].any()


def test_crossing_motion_counts_as_speed_and_no_number_gives_zeros():
    geometry, radar = _candidates([10.0], [0.0], [6.0])
    assert candidate_speed(radar, geometry)[0].tolist() == pytest.approx([6.0])
    assert candidate_speed(None, geometry).tolist() == [[0.0]]
    numbers, padding = _numbers("the crossing pedestrian")
    assert not compare_features(geometry, radar, numbers, padding).any()


def test_the_stage_reads_the_comparisons(untrained_model, random_scene):
    model = untrained_model("referent", text_encoder="gru", operating_threshold=0.0)
    # The comparisons follow the geometry and context, before the subset features.
    start = geometry_width(model.grounding.stage.cfg) - SUBSET_FEATURES
    columns = slice(start, start + COMPARE_FEATURES)
    a, b = answers_without(model, *random_scene(), "cars faster than 10 m/s", columns)
    assert len(a) and not np.allclose(a, b, atol=1e-4)


def test_a_prompt_without_numbers_compares_nothing():
    # Without a number every comparison column is 0: returned at once (no comparison made),
    # the same zeros the comparisons give when the only number hides under the padding.
    geometry, radar = _candidates([5.0, 30.0], [0.0, 12.0], [0.0, 0.0])
    numbers, padding = _numbers("the nearest car")
    quick = compare_features(geometry, radar, numbers, padding)
    assert quick.shape == (1, 2, COMPARE_FEATURES) and not quick.any()
    hidden = numbers.clone()
    hidden[0, -1] = _numbers("a car 30 m ahead")[0][0, 3]  # a number, but in the padding
    assert bool((hidden[..., 0] > 0.5).any())
    torch.testing.assert_close(compare_features(geometry, radar, hidden, padding), quick)
    with_number = compare_features(geometry, radar, *_numbers("cars 30 m ahead"))
    assert with_number.any()
