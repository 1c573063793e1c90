"""What the model takes and gives: point-cloud checks, encoded scenes, answers (:class:`Predictions`)
and their timings.

Input rules: points are numpy arrays or tensors ``(N, 4)`` (x, y, z, intensity) and ``(M, 7)``
(x, y, z, rcs, v_r, v_r_compensated, time), radar already in the LiDAR frame. NaN or inf raise
:class:`NonFiniteInputError` naming the sensor and row *before* anything reaches the network. An
empty array (a sensor that returned nothing) is fine; a missing required sensor (``None``)
raises :class:`MissingSensorError`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch
from torch import Tensor

from model.core.candidates import SceneCandidates
from model.core.grid import BevGrid
from scenes.language.reading import Reading

PointsLike = np.ndarray | Tensor


class NonFiniteInputError(ValueError):
    """A point cloud holds NaN or inf values."""


class MissingSensorError(ValueError):
    """The model needs a sensor's points that were not given."""


@dataclass(frozen=True)
class SceneTimings:
    """Milliseconds spent in :meth:`model.tpcnet.TPCNet.encode_scene`, per stage."""

    pillars: float
    backbone: float
    fusion: float
    detect: float = 0.0
    """``grounding="referent"``: neck, head, decoding and candidate description."""

    @property
    def total(self) -> float:
        return self.pillars + self.backbone + self.fusion + self.detect


@dataclass(frozen=True)
class GroundTimings:
    """Milliseconds spent in :meth:`model.tpcnet.TPCNet.ground`, per stage."""

    text: float
    dggf: float
    neck: float
    head: float
    decode: float
    referent: float = 0.0
    """``grounding="referent"``: the referent stage (then ``dggf``, ``neck``, ``head`` are 0)."""

    @property
    def total(self) -> float:
        return self.text + self.dggf + self.neck + self.head + self.decode + self.referent


@dataclass(frozen=True)
class SceneFeatures:
    """Text-independent features of one scene.

    Attributes:
        stages: ``(lr_1, lr_2, lr_3)``, each ``(1, C_i, H_i, W_i)`` on the model's device.
        num_lidar: LiDAR points given (before range filtering); 0 when unused.
        num_radar: Radar points given; 0 when unused.
        timings: Time per stage of the encoding.
        objects: ``grounding="referent"`` only: the text-agnostic detections of the scene as
            referent-stage candidates, and the detector's ``(3, H, W)`` sigmoid heatmaps.
        answerable: With labelled candidates (:mod:`model.core.labelled`): the first this many
            candidates are the labelled boxes, the only possible answers (the rest is context).
            None: every candidate may be an answer.
    """

    stages: tuple[Tensor, ...]
    num_lidar: int
    num_radar: int
    timings: SceneTimings
    objects: SceneCandidates | None = None
    detection_heatmaps: np.ndarray | None = None
    answerable: int | None = None


@dataclass(frozen=True)
class Predictions:
    """The answer to one prompt: what a grounding head returns
    (:meth:`model.grounding.interface.GroundingHead.answer`, the text encoder's time still 0) and
    :meth:`model.tpcnet.TPCNet.ground` gives (its time added); the one answer type from the model
    to the evaluation and the app (which read it as :class:`model.protocol.PredictionsView`).

    Attributes:
        boxes: ``(K, 7)`` float64 ``x, y, z, l, w, h, yaw``, LiDAR frame, sorted by score.
        scores: ``(K,)`` float64 in ``[0, 1]``.
        labels: ``(K,)`` int64 indices into the model's class set (``cfg.class_set``, channel order).
        classes: ``K`` class names.
        heatmaps: ``(C, H, W)`` float32 sigmoid heatmaps, one per class of the model's class set
            (``vod``: Car, Pedestrian, Cyclist) on ``grid``, ``heatmaps[c, iy, ix]``.
        grid: The head's BEV grid.
        prompt: The prompt as encoded (stripped).
        truncated: Whether the prompt exceeded the text encoder's token limit.
        timings: Time per stage of the grounding.
        reading: How the sentence was read (:func:`scenes.language.reading.read_prompt`: the
            texts grounded, one object or a set, a command); None from a head alone.
        note: A sentence for the person when the answer is not what was asked for ("no bus
            here"), else "".
    """

    boxes: np.ndarray
    scores: np.ndarray
    labels: np.ndarray
    classes: tuple[str, ...]
    heatmaps: np.ndarray
    grid: BevGrid
    prompt: str
    truncated: bool
    timings: GroundTimings
    reading: Reading | None = None
    note: str = ""

    def pick(self, rows: Sequence[int]) -> Predictions:
        """The boxes at ``rows`` only, in that order (the rest of the answer unchanged)."""
        rows = np.asarray(rows, dtype=np.int64).reshape(-1)
        return replace(
            self,
            boxes=self.boxes[rows],
            scores=self.scores[rows],
            labels=self.labels[rows],
            classes=tuple(self.classes[i] for i in rows),
        )


def as_points(points: PointsLike, num_features: int, name: str) -> Tensor:
    """Validate one cloud and return it as a float32 CPU-or-device tensor ``(N, F)``.

    Raises:
        TypeError: not an array or tensor.
        ValueError: wrong shape.
        NonFiniteInputError: NaN or inf values (names the first bad row).
    """
    if isinstance(points, np.ndarray):
        tensor = torch.from_numpy(np.ascontiguousarray(points, dtype=np.float32))
    elif isinstance(points, Tensor):
        tensor = points.detach().to(torch.float32)
    else:
        raise TypeError(f"{name} must be a numpy array or a torch tensor, got {type(points)}")
    if tensor.numel() == 0:
        return tensor.reshape(0, num_features)
    if tensor.dim() != 2 or tensor.shape[1] != num_features:
        raise ValueError(f"{name} must have shape (N, {num_features}), got {tuple(tensor.shape)}")
    # One sum is finite exactly when every value is (or it overflowed: then look row by row).
    if not bool(torch.isfinite(tensor.sum())) and not bool(torch.isfinite(tensor).all()):
        finite = torch.isfinite(tensor).all(dim=1)
        row = int(torch.nonzero(~finite)[0, 0])
        raise NonFiniteInputError(
            f"{name} has NaN or inf values (first at row {row}: {tensor[row].tolist()}); "
            "remove or fix those points before running the model"
        )
    return tensor


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


class Clock:
    """Wall-clock lap timer in milliseconds (synchronising CUDA before each reading).

    Disabled (``enabled=False``, as in training) it returns 0 and never synchronises.
    """

    def __init__(self, device: torch.device, enabled: bool = True) -> None:
        self.device = device
        self.enabled = enabled
        if enabled:
            _sync(device)
        self.last = time.perf_counter()

    def lap(self) -> float:
        if not self.enabled:
            return 0.0
        _sync(self.device)
        now = time.perf_counter()
        ms, self.last = (now - self.last) * 1000.0, now
        return ms
