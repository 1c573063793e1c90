"""Prediction over a root by several processes, results in sample order.

Why: on a CPU, one ``encode_scene`` is many small operations, so a second torch thread inside it
gains almost nothing; frames predicted side by side in separate processes use every core. With
``workers = N``, this process and ``N - 1`` worker processes predict, each with one torch thread.
A worker is a fresh interpreter (the ``spawn`` start method: never ``fork`` after torch has
started its threads) that rebuilds the model from the evaluated one's checkpoint payload
(:class:`ModelSource`); every process runs the same
:class:`model.evaluation.predict.FramePredictor` as the in-process path, so all give the same
predictions.

- Work goes out by frame (:func:`frame_groups`): consecutive samples with one
  :func:`model.evaluation.predict.scene_key` are one task, so a shared scene is still encoded once.
- The workers are kept :data:`IN_FLIGHT_PER_WORKER` frames ahead; whenever the next result due is
  still a worker's, this process predicts the next frame not yet handed out, so it never waits
  idle (above all while the workers start: an interpreter, torch's import, the model's and
  MiniLM's loading, about 3 s on this 2-core machine).
- Results come back in sample order, without the points of the sample or the encoded features
  (the caller needs only labels, calibration and sidecar).
- An error (a malformed file, a checkpoint a worker cannot rebuild) is raised as the same
  exception with the same message when its sample's turn comes; the pool then stops: tasks not
  started are cancelled, running ones finish (one frame each, within the liveness limit, else
  the worker is killed) and the workers exit. Workers ignore SIGINT, so Ctrl-C interrupts this
  process only, which stops the pool the same way.
- A worker that dies (killed, crashed) or stops answering (SIGSTOP, a hang) ends the run within a
  bounded time with a :class:`model.evaluation.worker_watch.PredictionWorkerError`: one line
  naming the worker, its frame and what to do (:mod:`model.evaluation.worker_watch`: the limits
  are set from this process's own measured seconds per sample, :class:`Liveness`). Results are
  yielded only as they come in whole; the caller writes its files after the last one.
- :func:`auto_workers`: the usable cores (``os.sched_getaffinity``), but at most one process per
  :data:`MIN_FRAMES_PER_WORKER` frames: about the frames this process predicts while a worker
  starts, so a shorter split would not win its start back; 1 is the in-process path
  (:func:`model.evaluation.predict.iterate_predictions`).
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import signal
import tempfile
import time
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures import wait as wait_futures
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, fields, replace
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch
from tqdm import tqdm

from model.evaluation.predict import (
    FramePrediction,
    FramePredictor,
    PredictSettings,
    iterate_predictions,
    scene_key,
)
from model.evaluation.worker_watch import (
    DEFAULT_LIVENESS,
    Liveness,
    PredictionWorkerError,
    StartQueue,
    WorkerWatch,
)
from scenes.frame import FrameSource, Sample

if TYPE_CHECKING:
    from model.tpcnet import TPCNet

MIN_FRAMES_PER_WORKER = 40
"""Fewest distinct frames per predicting process that :func:`auto_workers` plans for (module
docstring): below ``2 * 40`` frames a split is predicted in-process."""

IN_FLIGHT_PER_WORKER = 2
"""Frame tasks handed to each worker process ahead (it never waits for the next; few, so that the
last frames end together)."""


def usable_cores() -> int:
    """The CPU cores this process may run on (``os.sched_getaffinity``; ``os.cpu_count``)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def auto_workers(frames: int, device: str = "cpu", cores: int | None = None) -> int:
    """Worker processes for ``frames`` distinct frames: ``min(cores, frames //
    MIN_FRAMES_PER_WORKER)``, at least 1; always 1 off the CPU (a GPU runs one model)."""
    if str(device) != "cpu":
        return 1
    cores = usable_cores() if cores is None else cores
    return max(1, min(cores, frames // MIN_FRAMES_PER_WORKER))


def frame_groups(root: FrameSource, ids: Sequence[str]) -> list[tuple[str, ...]]:
    """``ids`` cut into runs of consecutive samples of one frame (one :func:`scene_key`), in
    order: each run is one worker task, so its scene is encoded once."""
    groups: list[list[str]] = []
    last: object = None
    for sid in ids:
        key = scene_key(root, sid)
        if not groups or key != last:
            groups.append([])
        groups[-1].append(sid)
        last = key
    return [tuple(g) for g in groups]


@dataclass(frozen=True)
class ModelSource:
    """A model as a checkpoint file that each worker loads (on the CPU). A file, not bytes in the
    workers' start arguments: ``spawn`` writes those into a pipe that the child reads only after
    importing the main module, so a payload larger than the pipe would hold this process up
    (and forever, were the child to fail before reading it)."""

    path: Path

    @classmethod
    def of(cls, model: TPCNet, folder: Path) -> ModelSource:
        """Write ``model`` (weights, config, metadata) to ``folder/model.pt``."""
        from model.checkpoint import save_checkpoint
        from model.checkpoint_meta import CheckpointMeta

        meta = CheckpointMeta.of(model).to_dict()
        return cls(save_checkpoint(folder / "model.pt", model, **meta))

    def build(self) -> TPCNet:
        from model.checkpoint import load_checkpoint

        return load_checkpoint(self.path, "cpu")


_WORKER: FramePredictor | BaseException | None = None
"""This worker process's predictor, or the error that rebuilding it raised (re-raised by each
task, so that it reaches the main process as a task's error)."""

_STARTS: StartQueue | None = None
"""This worker process's queue of task starts (:mod:`model.evaluation.worker_watch`)."""


def _start_worker(
    source: ModelSource, root: FrameSource, settings: PredictSettings, starts: StartQueue
) -> None:
    """Worker initializer: one torch thread, SIGINT left to the main process, the model built."""
    global _WORKER, _STARTS
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    torch.set_num_threads(1)
    _STARTS = starts
    try:
        _WORKER = FramePredictor(source.build(), root, settings)
    except Exception as exc:  # raised again by the first task
        _WORKER = exc


def _predict_frame(task: int, ids: tuple[str, ...]) -> list[FramePrediction]:
    """Worker task ``task``: :func:`_predict_group` with this worker's predictor (its start said
    on the start queue first)."""
    if _STARTS is not None:
        _STARTS.put((task, os.getpid(), time.time()))
    if isinstance(_WORKER, BaseException):
        raise _WORKER
    assert _WORKER is not None, "worker not started"
    return _predict_group(_WORKER, ids)


def _predict_group(predictor: FramePredictor, ids: tuple[str, ...]) -> list[FramePrediction]:
    """Predict the samples of one frame (points dropped from the returned samples, the
    features not returned)."""
    out = []
    for sid in ids:
        pred = predictor.predict(predictor.read(sid))
        out.append(replace(pred, sample=_without_points(pred.sample), features=None))
    return out


def _without_points(sample: Sample) -> Sample:
    """``sample`` with empty ``(0, 4)`` LiDAR and ``(0, 7)`` radar arrays (nothing else
    changed)."""
    return replace(sample, lidar=sample.lidar[:0].copy(), radar=sample.radar[:0].copy())


def _shallow(obj: Any) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in fields(obj)}


def _result(
    future: Future[list[FramePrediction]], task: int, watch: WorkerWatch, starts: StartQueue
) -> list[FramePrediction]:
    """Task ``task``'s result, looking at the workers every :attr:`Liveness.poll_s` while it is
    not back.

    Raises:
        PredictionWorkerError: its worker died, or it is past its limit (module docstring).
    """
    while True:
        wait_futures([future], timeout=watch.liveness.poll_s)
        watch.heard(starts)
        if future.done():
            break
        error = watch.overdue(task)
        if error is not None:
            raise error
    try:
        return future.result()
    except BrokenProcessPool as exc:
        raise watch.died(starts) from exc


def _stop_pool(
    pool: ProcessPoolExecutor,
    watch: WorkerWatch,
    kill: bool,
) -> None:
    """Shut the pool down: tasks not started cancelled, running ones given their limit (none with
    ``kill``), then every worker still alive killed, so that this never waits on a worker that
    cannot finish (a stopped one)."""
    manager = getattr(pool, "_executor_manager_thread", None)
    if kill:
        watch.end()
    pool.shutdown(wait=False, cancel_futures=True)
    longest = max((len(g) for g in watch.groups), default=1)
    deadline = time.monotonic() + watch.liveness.task_limit(watch.seconds_per_sample, longest)
    for p in watch.known().values():
        p.join(timeout=max(0.0, deadline - time.monotonic()))
    watch.end()
    if manager is not None:
        manager.join()


def predictions(
    model: TPCNet,
    root: FrameSource,
    ids: Sequence[str],
    settings: PredictSettings,
    workers: int = 1,
    progress: bool = True,
    liveness: Liveness = DEFAULT_LIVENESS,
) -> Iterator[FramePrediction]:
    """Each sample's :class:`model.evaluation.predict.FramePrediction`, in the order of ``ids``:
    in this process (``workers <= 1``: :func:`model.evaluation.predict.iterate_predictions`) or
    by ``workers`` processes, this one and ``workers - 1`` spawned ones (module docstring; the
    model must be on the CPU and ``settings`` picklable; the predictions carry no features and
    their samples no points).

    Raises:
        PredictionWorkerError: a worker died or went past ``liveness``'s limits (one line).
    """
    groups = frame_groups(root, ids) if workers > 1 else []
    if len(groups) < 2:
        yield from iterate_predictions(model, root, ids, progress=progress, **_shallow(settings))
        return
    device = next((p.device for p in model.parameters()), torch.device("cpu"))
    if device.type != "cpu":
        raise ValueError(f"prediction workers run on the CPU; the model is on {device}")
    spawned = min(workers, len(groups)) - 1
    here = FramePredictor(model, root, settings)
    folder = tempfile.TemporaryDirectory(prefix="talk2pc-predict-")
    context = multiprocessing.get_context("spawn")
    starts = context.SimpleQueue()
    pool = ProcessPoolExecutor(
        max_workers=spawned,
        mp_context=context,
        initializer=_start_worker,
        initargs=(ModelSource.of(model, Path(folder.name)), root, settings, starts),
    )
    processes: Mapping[int, BaseProcess] = pool._processes  # type: ignore[attr-defined]
    # (the pool's own pid -> process map, filled as it starts workers: their exit status)
    watch = WorkerWatch(liveness, groups, processes)
    ended_by_watch = False
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # this process is one of the workers
    bar = tqdm(total=len(ids), desc="predict", unit="frame", disable=not progress)
    slots: dict[int, Future[list[FramePrediction]] | list[FramePrediction] | Exception] = {}
    sent = 0  # groups handed out, in order
    try:
        with bar:
            for index in range(len(groups)):
                while True:
                    queued = sum(isinstance(v, Future) and not v.done() for v in slots.values())
                    while sent < len(groups) and queued < spawned * IN_FLIGHT_PER_WORKER:
                        try:
                            future = pool.submit(_predict_frame, sent, groups[sent])
                        except BrokenProcessPool as exc:  # a worker died since the last look
                            ended_by_watch = True
                            raise watch.died(starts) from exc
                        future.add_done_callback(functools.partial(_finished, watch, sent))
                        slots[sent] = future
                        sent, queued = sent + 1, queued + 1
                    head = slots[index]
                    waiting = isinstance(head, Future) and not head.done()
                    failed = any(isinstance(v, Exception) for v in slots.values())
                    if not (waiting and sent < len(groups) and not failed):
                        break
                    start = time.perf_counter()
                    try:  # the next group here, while the workers' are not back
                        slots[sent] = _predict_group(here, groups[sent])
                        watch.measured(time.perf_counter() - start, len(groups[sent]))
                    except Exception as exc:  # raised when its turn comes
                        slots[sent] = exc
                    sent += 1
                done = slots.pop(index)
                if isinstance(done, Exception):
                    raise done
                if isinstance(done, Future):
                    try:
                        done = _result(done, index, watch, starts)
                    except PredictionWorkerError:
                        ended_by_watch = True
                        raise
                for pred in done:
                    bar.update(1)
                    yield pred
    finally:
        torch.set_num_threads(threads)
        _stop_pool(pool, watch, kill=ended_by_watch)
        starts.close()
        folder.cleanup()


def _finished(watch: WorkerWatch, task: int, future: Future[list[FramePrediction]]) -> None:
    """A worker task's done callback (the pool's thread): a sign of life, unless the pool broke
    (then the task's start still says which worker held it)."""
    if future.cancelled() or isinstance(future.exception(), BrokenProcessPool):
        return
    watch.finished(task)
