"""bench.studies.sensor_stats: the tolerance rule, the three-frame sampling interval and the table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.studies.sensor_stats import (
    REAL_FRAMES,
    FrameStats,
    Row,
    collect,
    markdown,
    summary_rows,
    three_frame_interval,
    within_band,
)


def _frame(lidar_fov: int, ped_counts: list[int]) -> FrameStats:
    return FrameStats(
        lidar_fov=lidar_fov,
        intensities=np.array([40.0, 108.0, 215.0], dtype=np.float32),
        lidar_per_actor={("Pedestrian", 1): ped_counts} if ped_counts else {},
        radar_fov_single=210,
        radar_fov_all=900,
        rcs=np.array([-27.0, -13.0, 2.0]),
        radar_per_vru=[4],
        referable=8,
        referable_vru=6,
        clutter=5,
    )


def test_within_band_is_25_percent_either_side_and_covers_ranges():
    assert within_band(125.0, 100.0) and within_band(75.0, 100.0)
    assert not within_band(126.0, 100.0) and not within_band(74.0, 100.0)
    assert within_band(290.0, 197.0, 236.0) and not within_band(300.0, 197.0, 236.0)


def test_three_frame_interval_samples_three_frames_and_skips_empty_bins():
    stats = [_frame(1000 * (i + 1), [i * 10] if i % 2 else []) for i in range(20)]
    lo, hi = three_frame_interval(stats, lambda ss: float(np.mean([s.lidar_fov for s in ss])))
    assert REAL_FRAMES == 3
    assert 2000 <= lo < hi <= 19000  # means of 3 distinct frames of 1000..20000
    lo, hi = three_frame_interval(stats, lambda ss: math.nan)
    assert math.isnan(lo) and math.isnan(hi)


def test_rows_flag_a_statistic_outside_tolerance():
    good = summary_rows([_frame(34_300, [130]) for _ in range(6)])
    by_name = {r.statistic: r for r in good}
    total = by_name["LiDAR points in the camera field of view"]
    assert total.within and total.consistent
    assert by_name["LiDAR points on a pedestrian at 15-30 m (median)"].within
    assert by_name["radar RCS p10 / p50 / p90 (dBsm, single scan)"].within
    bad = {r.statistic: r for r in summary_rows([_frame(60_000, [40]) for _ in range(6)])}
    assert not bad["LiDAR points in the camera field of view"].within
    assert not bad["LiDAR points on a pedestrian at 15-30 m (median)"].within
    text = markdown(list(bad.values()), worlds=6, seed=0, seconds=1.0)
    assert "| **no** |" in text and "statistics within tolerance" in text


@pytest.mark.parametrize("worlds", [2])
def test_collect_measures_generated_worlds(worlds):
    stats = collect(worlds, seed=5)
    assert len(stats) == worlds
    assert all(s.lidar_fov > 1000 and s.radar_fov_single > 0 for s in stats)
    rows = summary_rows(stats)
    assert all(isinstance(r, Row) for r in rows) and len(rows) == 12
