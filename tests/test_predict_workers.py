"""Prediction by worker processes (model/evaluation/predict_pool.py): the same predictions and
report as in-process, errors raised as in-process with the pool shut down, the automatic count."""

from __future__ import annotations

import multiprocessing
from pathlib import Path

import numpy as np
import pytest

from model.checkpoint import DEFAULT_CHECKPOINT, load_checkpoint
from model.evaluate import main
from model.evaluation.predict import PredictSettings
from model.evaluation.predict_pool import (
    MIN_FRAMES_PER_WORKER,
    auto_workers,
    frame_groups,
    predictions,
)
from model.evaluation.report import class_noun_of, evaluate_predictions
from model.evaluation.report_file import SECONDS
from scenes.talk2radar.root import Talk2RadarRoot


@pytest.fixture(scope="module")
def trained():
    return load_checkpoint(DEFAULT_CHECKPOINT)


def _report_numbers(report) -> dict:
    out = report.to_dict()
    out.pop(SECONDS)  # timing, the one figure that may differ
    return out


def test_auto_workers():
    assert auto_workers(10, cores=2) == 1  # too few frames to pay for starting a worker
    assert auto_workers(2 * MIN_FRAMES_PER_WORKER - 1, cores=2) == 1
    assert auto_workers(2 * MIN_FRAMES_PER_WORKER, cores=2) == 2
    assert auto_workers(300, cores=2) == 2
    assert auto_workers(300, cores=16) == 300 // MIN_FRAMES_PER_WORKER
    assert auto_workers(300, device="cuda", cores=16) == 1
    assert auto_workers(0, cores=4) == 1


def test_two_workers_predict_and_report_as_one_process(tmp_path, write_tiny_root, trained):
    root = Talk2RadarRoot(write_tiny_root(tmp_path / "root", frames=5))
    ids = root.ids("test")
    settings = PredictSettings(
        score_threshold=0.05, min_label_score=0.1, extra_prompts=class_noun_of
    )
    here = list(predictions(trained, root, ids, settings, workers=1, progress=False))
    pooled = list(predictions(trained, root, ids, settings, workers=2, progress=False))
    assert [p.sample.sample_id for p in pooled] == list(ids)
    assert any(len(p.boxes) for p in here)  # the comparison compares boxes
    for a, b in zip(here, pooled, strict=True):
        assert a.classes == b.classes and a.scene_key == b.scene_key
        np.testing.assert_allclose(b.boxes, a.boxes, atol=1e-5)
        np.testing.assert_allclose(b.scores, a.scores, atol=1e-5)
        assert [lab.name for lab in a.labels] == [lab.name for lab in b.labels]
        assert a.extra.keys() == b.extra.keys() == {"the cars"}
        np.testing.assert_allclose(
            b.extra["the cars"].scores, a.extra["the cars"].scores, atol=1e-5
        )
        assert b.features is None and len(b.sample.lidar) == 0  # points stay in the worker
        np.testing.assert_array_equal(b.sample.calib.Tr_velo_to_cam, a.sample.calib.Tr_velo_to_cam)
        assert b.sample.prompt == a.sample.prompt and b.sample.labels == a.sample.labels
    one = evaluate_predictions(trained, root, ids, progress=False, baselines=True, workers=1)
    two = evaluate_predictions(trained, root, ids, progress=False, baselines=True, workers=2)
    assert _report_numbers(two) == _report_numbers(one)
    assert multiprocessing.active_children() == []


def test_a_worker_error_is_one_line_naming_the_file(tmp_path, write_tiny_root, capsys):
    root = write_tiny_root(tmp_path / "root", frames=4)
    bad = sorted(Path(root).glob("lidar/training/velodyne/*.bin"))[0]  # the first frame: a
    bad.write_bytes(bad.read_bytes()[:-3])  # worker's (not a whole number of points)
    args = ["--data", str(root), "--out", str(tmp_path / "o"), "--no-baselines"]

    def error_lines() -> list[str]:
        err = capsys.readouterr().err  # tqdm's bar, then the error
        return [line for line in err.splitlines() if line.startswith("error:")]

    assert main([*args, "--workers", "1"]) == 2
    alone = error_lines()
    assert main([*args, "--workers", "2"]) == 2
    pooled = error_lines()
    assert pooled == alone and len(pooled) == 1 and str(bad) in pooled[0]
    assert multiprocessing.active_children() == []


def test_frame_groups_keep_the_samples_of_one_frame_together(tmp_path):
    from scenes.geometry.calib import vod_lidar_calibration, vod_radar_calibration
    from scenes.talk2radar.root import Talk2RadarWriter

    rng = np.random.default_rng(0)
    writer = Talk2RadarWriter(tmp_path)
    ids = []
    for world, samples in enumerate((2, 1, 3)):
        files = writer.write_sensors(
            f"w{world}",
            rng.uniform(-10, 10, (50, 4)).astype(np.float32),
            rng.uniform(-10, 10, (5, 7)).astype(np.float32),
            vod_lidar_calibration(),
            vod_radar_calibration(),
        )
        for _ in range(samples):
            box = np.array([[15.0, 1.0, -0.9, 4.0, 1.8, 1.5, 0.2]])
            ids.append(writer.write_sample(len(ids), files, box, ["Car"], "the car"))
    root = Talk2RadarRoot(tmp_path)
    assert frame_groups(root, ids) == [tuple(ids[:2]), (ids[2],), tuple(ids[3:])]


def test_labelled_candidates_in_workers(real_format_roots, trained):
    from scenes.talk2radar.scene_labels import SceneLabels

    t2r, vod = real_format_roots
    assert trained.cfg.grounding == "referent"
    root = Talk2RadarRoot(t2r, sidecar=False)
    ids = [i for split in ("train", "val", "test") for i in root.ids(split)]
    kw = dict(progress=False, baselines=True, scene_labels=SceneLabels(vod), candidates="labels")
    one = evaluate_predictions(trained, root, ids, workers=1, **kw)
    two = evaluate_predictions(trained, root, ids, workers=2, **kw)
    assert _report_numbers(two) == _report_numbers(one)
    assert one.grounding is not None and one.grounding.overall.prompts == len(ids)
