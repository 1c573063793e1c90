"""The model behind the app: a worker pool, a model lock and the scene-feature cache.

- Model calls never run on viser's event loop nor in its callback threads: callbacks hand them to
  :meth:`GroundingEngine.submit` (a small pool of daemon worker threads) and return at once, so a
  slow prompt of one browser never freezes another browser's GUI. The workers are daemons so that
  Ctrl-C stops the app at once even while a scene is being encoded (a standard
  ``ThreadPoolExecutor`` would hold the interpreter's exit until the model call ends).
- One lock guards the model (the module and its text cache are not meant for concurrent calls;
  on a 2-core machine running two forward passes at once gains nothing).
- ``encode_scene`` runs once per (sample, modality): the features stay in an LRU cache
  (:class:`scenes.utils.lru.LRUCache`), so each prompt runs only ``ground``.
  :meth:`GroundingEngine.prefetch` encodes a frame as soon as it is shown, before anyone types.
- Modality: ``"lidar"`` and ``"radar"`` re-encode the scene with the other sensor's points emptied
  (a ``(0, F)`` array), which a model trained on both sensors accepts. A single-sensor model only
  offers its own sensor.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any, Generic, Literal, TypeVar

import numpy as np

from model import GroundingModel, ModelSettings, PredictionsView, model_classes
from scenes.frame import Sample
from scenes.geometry.classes import ClassSet
from scenes.utils.lru import LRUCache

log = logging.getLogger(__name__)

Modality = Literal["both", "lidar", "radar"]

MODALITY_LABELS: dict[str, Modality] = {
    "LiDAR + radar": "both",
    "LiDAR": "lidar",
    "Radar": "radar",
}
"""GUI label -> modality."""


Features = TypeVar("Features")
"""A model's encoded scene (``model.core.features.SceneFeatures``); the engine only caches it."""

Predictions = PredictionsView
"""What the app reads of one answer (:class:`model.protocol.PredictionsView`)."""


def initial_threshold(model: GroundingModel, default: float) -> float:
    """The score threshold the query panel starts at: the checkpoint's operating threshold
    (:func:`model.evaluation.predict.operating_threshold`, chosen on a validation split by
    ``python -m model.calibrate``) so that the app shows the model's answer set, else the
    grounding head's ``uncalibrated_threshold``, else ``default`` (a model without a config)."""
    if _config(model) is None:
        return float(default)
    from model import operating_threshold

    return operating_threshold(model)  # type: ignore[arg-type]


def model_modalities(model: GroundingModel) -> tuple[Modality, ...]:
    """The modalities a model can answer with: all three for a two-sensor model, otherwise its
    own sensor (read from ``model.cfg.modalities``; a model without a config counts as both)."""
    cfg = _config(model)
    built = "both" if cfg is None else cfg.modalities
    if built == "lidar":
        return ("lidar",)
    if built == "radar":
        return ("radar",)
    return ("both", "lidar", "radar")


def _config(model: GroundingModel) -> ModelSettings | None:
    """The model's configuration, None for a model without one."""
    return getattr(model, "cfg", None)


def sensor_inputs(sample: Sample, modality: Modality) -> tuple[np.ndarray, np.ndarray]:
    """The ``(lidar (N, 4), radar (M, 7))`` arrays to encode for a modality: the sensor left out
    becomes an empty array (zero points)."""
    lidar = np.asarray(sample.lidar, dtype=np.float32).reshape(-1, 4)
    radar = np.asarray(sample.radar, dtype=np.float32).reshape(-1, 7)
    if modality == "lidar":
        radar = np.zeros((0, 7), np.float32)
    elif modality == "radar":
        lidar = np.zeros((0, 4), np.float32)
    elif modality != "both":
        raise ValueError(f"unknown modality {modality!r}; use one of both, lidar, radar")
    return lidar, radar


@dataclass(frozen=True)
class Answer:
    """The model's answer to one prompt on one frame.

    Attributes:
        predictions: What ``model.ground`` returned (:class:`Predictions`: boxes, scores,
            classes, heatmaps, grid).
        sample_id: The frame's sample id.
        modality: Sensors used.
        prompt: The prompt as sent.
        score_threshold: Threshold applied by the decoder.
        encode_ms: Time spent encoding the scene for this answer (0 when cached).
        ground_ms: Time of ``ground``.
        waited_ms: Time spent waiting for the model lock (other browsers' work).
    """

    predictions: Predictions
    sample_id: str
    modality: Modality
    prompt: str
    score_threshold: float
    encode_ms: float
    ground_ms: float
    waited_ms: float

    @property
    def cached(self) -> bool:
        """Whether the scene features came from the cache."""
        return self.encode_ms == 0.0


class DaemonWorkers:
    """A minimal thread pool of daemon threads: ``submit(fn, *args) -> Future``.

    Args:
        workers: Number of threads.
        name: Thread name prefix.
    """

    def __init__(self, workers: int, name: str) -> None:
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._closed = False
        self._threads = [
            threading.Thread(target=self._run, name=f"{name}_{i}", daemon=True)
            for i in range(max(1, workers))
        ]
        for thread in self._threads:
            thread.start()

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future:
        """Queue ``fn(*args)``; its result or exception ends up in the returned future."""
        if self._closed:
            raise RuntimeError("the worker pool is shut down")
        future: Future = Future()
        self._queue.put((future, fn, args))
        return future

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            future, fn, args = item
            if not future.set_running_or_notify_cancel():
                continue
            try:
                result = fn(*args)
            except BaseException as exc:
                future.set_exception(exc)
            else:
                future.set_result(result)

    def shutdown(self) -> None:
        """Cancel queued jobs and let the threads end (a running job finishes in the background)."""
        self._closed = True
        while True:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                break
            if item is not None:
                item[0].cancel()
        for _ in self._threads:
            self._queue.put(None)


class GroundingEngine(Generic[Features]):
    """Runs a model for the app: thread pool, model lock, scene-feature cache.

    Args:
        model: The model (in eval mode).
        feature_cache_size: Encoded (sample, modality) pairs kept.
        workers: Worker threads.
    """

    def __init__(
        self, model: GroundingModel[Features], feature_cache_size: int = 8, workers: int = 2
    ) -> None:
        self.model = model
        self.modalities = model_modalities(model)
        self.classes: ClassSet = model_classes(model)
        """The model's class set (its legend, answer words and the Annotate tab's classes)."""
        self.feature_cache_size = max(1, feature_cache_size)
        self.workers = DaemonWorkers(workers, "talk2pc-model")
        self._model_lock = threading.Lock()
        self._features: LRUCache[tuple[str, Modality, bool], Features] = LRUCache(
            self.feature_cache_size
        )
        self.encode_calls = 0
        self.ground_calls = 0

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future:
        """Run ``fn(*args)`` in the worker pool; exceptions are logged (and kept in the future)."""
        future = self.workers.submit(fn, *args)
        future.add_done_callback(_log_failure)
        return future

    def cached(self, sample_id: str, modality: Modality, labelled: bool = False) -> bool:
        """Whether the features of (sample, modality) are cached (with labelled candidates)."""
        return (sample_id, modality, labelled) in self._features

    def _check_modality(self, modality: Modality) -> None:
        if modality not in self.modalities:
            raise ValueError(
                f"this model answers with {', '.join(self.modalities)} only, not {modality!r}"
            )

    def _encode_locked(
        self, sample: Sample, modality: Modality, candidates: object | None = None
    ) -> tuple[Features, float]:
        """Features of (sample, modality) and the encoding time (0 when cached); hold the lock.
        ``candidates``: the frame's labelled boxes for the referent stage to choose among
        (``model.LabelledBoxes``), None for the detector's proposals."""
        key = (sample.sample_id, modality, candidates is not None)
        cached = self._features.get(key)
        if cached is not None:
            return cached, 0.0
        lidar, radar = sensor_inputs(sample, modality)
        start = time.perf_counter()
        if candidates is None:
            features = self.model.encode_scene(lidar, radar)
        else:
            features = self.model.encode_scene(lidar, radar, candidates=candidates)
        elapsed = (time.perf_counter() - start) * 1000.0
        self.encode_calls += 1
        self._features.put(key, features)
        return features, max(elapsed, 1e-3)

    def encode(
        self, sample: Sample, modality: Modality, candidates: object | None = None
    ) -> tuple[Features, float]:
        """Encode (or fetch from the cache) one scene (with labelled ``candidates``: as
        :meth:`answer`); returns ``(features, encode_ms)``."""
        self._check_modality(modality)
        with self._model_lock:
            return self._encode_locked(sample, modality, candidates)

    def prefetch(
        self, sample: Sample, modality: Modality, candidates: object | None = None
    ) -> Future:
        """Encode a scene in the background (no-op when cached)."""
        return self.submit(self.encode, sample, modality, candidates)

    def answer(
        self,
        sample: Sample,
        modality: Modality,
        prompt: str,
        score_threshold: float,
        candidates: object | None = None,
    ) -> Answer:
        """Answer ``prompt`` on ``sample`` (blocking; call it through :meth:`submit`)."""
        self._check_modality(modality)
        queued = time.perf_counter()
        with self._model_lock:
            waited = (time.perf_counter() - queued) * 1000.0
            features, encode_ms = self._encode_locked(sample, modality, candidates)
            start = time.perf_counter()
            predictions = self.model.ground(features, prompt, score_threshold=score_threshold)
            ground_ms = (time.perf_counter() - start) * 1000.0
            self.ground_calls += 1
        return Answer(
            predictions=predictions,
            sample_id=sample.sample_id,
            modality=modality,
            prompt=prompt,
            score_threshold=score_threshold,
            encode_ms=encode_ms,
            ground_ms=ground_ms,
            waited_ms=waited,
        )

    def warm_up(self, prompt: str = "the car ahead") -> Future:
        """Run one tiny encode + ground in the background (loads the text encoder's weights)."""

        def run() -> None:
            start = time.perf_counter()
            with self._model_lock:
                empty_lidar, empty_radar = (
                    np.zeros((0, 4), np.float32),
                    np.zeros((0, 7), np.float32),
                )
                features = self.model.encode_scene(empty_lidar, empty_radar)
                self.model.ground(features, prompt)
            log.info("model warmed up in %.1f s", time.perf_counter() - start)

        return self.submit(run)

    def close(self) -> None:
        """Stop the worker pool (pending jobs are cancelled, running ones finish)."""
        self.workers.shutdown()


def _log_failure(future: Future) -> None:
    if future.cancelled():
        return
    exc = future.exception()
    if exc is not None:
        log.error("background job failed", exc_info=exc)
