"""bench.floor's pieces: real-size VoD-layout frames read back, the FLOPs split by stage, the
floor and ratio of a timed call."""

from __future__ import annotations

import math

import numpy as np

from bench.perf.floor_measure import ENCODE_STAGES, TimedCall, encode_flops, matmul_rate
from bench.perf.vod_frames import LIDAR_POINTS, RADAR_POINTS, vod_frames
from model.checkpoint import load_checkpoint
from scenes.talk2radar.layout import VELODYNE, sample_file
from tests.decode_reference import CHECKPOINT


def test_vod_frames_have_vods_sizes_and_the_stage_flops_add_up(tmp_path):
    (frame,) = vod_frames(tmp_path / "vod", 1)
    assert LIDAR_POINTS[0] <= len(frame.lidar) <= LIDAR_POINTS[1]
    assert RADAR_POINTS[0] <= len(frame.radar) <= RADAR_POINTS[1]
    assert frame.prompts and frame.lidar.dtype == np.float32 and frame.radar.shape[1] == 7
    # Read back from the VoD layout: the radar tree is the single scan, in the radar's frame.
    assert sample_file(tmp_path / "vod" / "radar", VELODYNE, frame.sample_id).is_file()
    model = load_checkpoint(CHECKPOINT).eval()
    flops = encode_flops(model, frame)
    assert sum(flops[s] for s in ENCODE_STAGES) == flops["total"] > 0
    assert flops["backbone"] > 0 and flops["fusion"] > 0 and flops["detect"] >= flops["head"] > 0


def test_a_calls_floor_and_ratio():
    call = TimedCall("encode", "00000", 100.0, 30.0, {"pillars": 5.0, "detect": 1.0},
                     {"total": 10**9, "pillars": 0, "detect": 5 * 10**8})  # fmt: skip
    assert call.floor_ms() == 10.0 and call.ratio() == 3.0  # 1 GFLOP at 100 GFLOP/s: 10 ms
    assert call.ratio("detect") == 0.2 and math.isnan(call.ratio("pillars"))
    assert matmul_rate(calls=2, n=128) > 0
