"""Prediction by worker processes (model/evaluation/predict_pool.py): the same predictions and
report as in-process, errors raised as in-process with the pool shut down, the automatic count;
a worker that dies or stops answering ends the run in bounded time with one line (issue 39)."""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import re
import signal
import threading
import time
from collections.abc import Callable, Iterator
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
from model.evaluation.report_file import SECONDS
from model.evaluation.talk2radar import class_noun_of, evaluate_predictions
from model.evaluation.worker_watch import Liveness, PredictionWorkerError, WorkerWatch
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


# ------------------------------------------------------------------ workers that die or freeze


@contextlib.contextmanager
def _no_worker_left() -> Iterator[None]:
    """Whatever a test leaves: no worker stays (a stopped one is killed)."""
    try:
        yield
    finally:
        for child in multiprocessing.active_children():
            child.kill()
            child.join()


def _on_first_worker(action: Callable[[int], None]) -> threading.Thread:
    """A thread that calls ``action(pid)`` on the first worker process as soon as it exists."""

    def watch() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            children = multiprocessing.active_children()
            if children:
                action(children[0].pid)
                return
            time.sleep(0.01)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def _worker_stream(trained, root: Talk2RadarRoot, liveness: Liveness) -> Iterator:
    settings = PredictSettings(score_threshold=0.05, min_label_score=0.1)
    return predictions(trained, root, root.ids("test"), settings, 2, False, liveness)


@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGSTOP], ids=["killed", "stopped"])
def test_a_worker_that_dies_or_stops_mid_run_is_named_in_one_line(
    tmp_path, write_tiny_root, trained, signum
):
    """After the first result, the worker is killed (or stopped): the run ends with one line
    naming it (pid, state, its frame) and what to do, within the limit, and no worker stays.
    Before the liveness check a stopped worker was waited on forever, a killed one was a
    BrokenProcessPool traceback."""
    root = Talk2RadarRoot(write_tiny_root(tmp_path / "root", frames=8))
    liveness = Liveness(floor_s=2.0, start_s=600.0, factor=1.0, poll_s=0.05)
    with _no_worker_left():
        stream = _worker_stream(trained, root, liveness)
        first = next(stream)
        assert first.sample.sample_id == root.ids("test")[0]  # the worker's: it has started
        (worker,) = multiprocessing.active_children()
        os.kill(worker.pid, signum)
        start = time.monotonic()
        with pytest.raises(PredictionWorkerError) as caught:
            list(stream)
        took = time.monotonic() - start
        assert multiprocessing.active_children() == []
    line = str(caught.value)
    assert "\n" not in line and f"prediction worker 1 of 1 (pid {worker.pid})" in line, line
    assert "run the command again, or with --workers 1" in line
    if signum == signal.SIGKILL:
        assert "killed by SIGKILL" in line and "out-of-memory" in line
        assert took < 30
    else:
        assert "stopped (SIGSTOP" in line and re.search(r"samples? \d{5}", line), line
        assert took < 2.0 + 30  # the limit (the floor here), then the look and the kill


def test_a_dead_worker_is_named_after_the_pool_forgot_it():
    """The pool's manager may empty its process map once the pool breaks, before the error is
    made: the watch names the worker from what it saw at an earlier look (under load the error
    was once a bare "a prediction worker ended abruptly")."""
    context = multiprocessing.get_context("fork")
    worker = context.Process(target=time.sleep, args=(60,))
    worker.start()
    starts = context.SimpleQueue()
    processes = {worker.pid: worker}
    watch = WorkerWatch(Liveness(), [("00001",)], processes)
    watch.heard(starts)  # a look while the pool still lists it
    os.kill(worker.pid, signal.SIGKILL)
    worker.join(5)
    processes.clear()  # the broken pool's manager
    line = str(watch.died(starts))
    assert f"prediction worker 1 of 1 (pid {worker.pid}) killed by SIGKILL" in line, line


@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGSTOP], ids=["killed", "stopped"])
def test_evaluate_with_a_dead_or_stopped_worker_is_one_line_and_writes_nothing(
    tmp_path, write_tiny_root, capsys, signum
):
    """``model.evaluate --workers 2``, its worker killed (or stopped) as soon as it exists: exit
    2, one ``error:`` line naming the worker, no prediction folder, no JSON."""
    root = write_tiny_root(tmp_path / "root", frames=6)
    out, report = tmp_path / "preds", tmp_path / "report.json"
    args = ["--data", str(root), "--out", str(out), "--json", str(report), "--workers", "2"]
    with _no_worker_left():
        pids: list[int] = []
        _on_first_worker(lambda pid: (pids.append(pid), os.kill(pid, signum)))
        start = time.monotonic()
        code = main([*args, "--worker-timeout", "2", "--no-baselines"])
        took = time.monotonic() - start
        assert multiprocessing.active_children() == []
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err[-3000:]
    assert f"(pid {pids[0]})" in lines[0] and "--workers 1" in lines[0], lines
    assert not out.exists() and not report.exists()
    assert took < 90  # the start allowance (3 x 2 s) and this process's own frames


def test_liveness_limits_follow_the_measured_frame_time():
    liveness = Liveness(factor=20.0, floor_s=20.0, start_s=60.0)
    assert liveness.task_limit(None, 3) == 20.0
    assert liveness.task_limit(0.1, 3) == 20.0  # 6 s of work: the floor
    assert liveness.task_limit(0.5, 4) == pytest.approx(40.0)
    assert Liveness.with_floor(2.0) == Liveness(floor_s=2.0, start_s=6.0)
    with pytest.raises(ValueError, match="floor_s must be > 0"):
        Liveness(floor_s=0.0)
