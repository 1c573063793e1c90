"""The training data of the referent path: one or several roots, each with its source and weight.

``python -m model.train --data ROOT [--data ROOT2 ...] [--data-weight W ...] [--scene-labels VOD
...]``: each ``--data`` root is one :class:`RootSpec`. ``--data-weight`` and ``--scene-labels`` pair
with the ``--data`` roots in order (give ``none`` for a root without scene labels; fewer values
than roots leave the rest at weight 1 and without scene labels). A root given scene labels, or one
without a ``meta/`` folder (a release as it comes), trains on its labels and given prompts and
never reads a sidecar; a synthetic root with its sidecar trains on generated prompts
(:class:`scenes.datasets.frames.FrameDataset`). So one command can pre-train on our world and
fine-tune on a user's: ``--data data/synth --data T2R --scene-labels none --scene-labels VOD``.

:class:`MixedFrames` is the epoch over several roots: the items of a root of weight ``w`` are seen
``w`` times per epoch on average (``floor(w)`` times each, plus a random ``w - floor(w)`` share of
them, drawn per epoch from ``(seed, epoch)``), so an epoch's length is fixed and a resumed run
draws the same epoch again.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from torch.utils.data import Dataset

from scenes.datasets.frames import FrameDataset, FrameItem
from scenes.talk2radar.scene_labels import SceneLabels

NO_SCENE_LABELS = "none"
"""The ``--scene-labels`` value of a root that has none."""


class DataSpecError(ValueError):
    """The ``--data`` / ``--data-weight`` / ``--scene-labels`` values do not fit together."""


@dataclass(frozen=True)
class RootSpec:
    """One training root.

    Attributes:
        path: The Talk2Radar root.
        weight: Times each of its frames is seen per epoch, on average (> 0).
        scene_labels: A View-of-Delft root with the frames' full labels, or None.
    """

    path: str
    weight: float = 1.0
    scene_labels: str | None = None


def root_specs(
    data: Sequence[str], weights: Sequence[float] = (), scene_labels: Sequence[str] = ()
) -> tuple[RootSpec, ...]:
    """Pair the ``--data``, ``--data-weight`` and ``--scene-labels`` values (module docstring).

    Raises:
        DataSpecError: no root, more weights or scene-label roots than ``--data`` roots, or a
            weight that is not a positive finite number.
    """
    if not data:
        raise DataSpecError("--data: give at least one root")
    for flag, values in (("--data-weight", weights), ("--scene-labels", scene_labels)):
        if len(values) > len(data):
            raise DataSpecError(
                f"{flag} given {len(values)} times for {len(data)} --data roots; they pair in order"
            )
    out = []
    for i, path in enumerate(data):
        weight = float(weights[i]) if i < len(weights) else 1.0
        if not math.isfinite(weight) or weight <= 0:
            raise DataSpecError(f"--data-weight {weights[i]!r} of {path}: must be a number > 0")
        labels = scene_labels[i] if i < len(scene_labels) else None
        out.append(RootSpec(path, weight, None if labels in (None, NO_SCENE_LABELS) else labels))
    return tuple(out)


def frame_dataset(spec: RootSpec, split: str, **kwargs: object) -> FrameDataset:
    """The :class:`FrameDataset` of one root's ``split`` (its source chosen as the module says)."""
    labels = None if spec.scene_labels is None else SceneLabels(spec.scene_labels)
    return FrameDataset(spec.path, split, scene_labels=labels, **kwargs)  # type: ignore[arg-type]


class MixedFrames(Dataset):
    """Several :class:`FrameDataset`\\ s as one epoch, each root at its weight (module docstring).

    Item ``j`` of an epoch is frame :meth:`resolve` ``(j)`` of the concatenation of the roots.
    """

    def __init__(self, datasets: Sequence[FrameDataset], weights: Sequence[float], seed: int = 0):
        if len(datasets) != len(weights) or not datasets:
            raise DataSpecError("MixedFrames needs one weight per dataset")
        self.datasets = list(datasets)
        self.weights = [float(w) for w in weights]
        self.seed = seed
        self.offsets = np.cumsum([0] + [len(d) for d in self.datasets])
        self.epoch = -1
        self.set_epoch(0)

    def _table(self, epoch: int) -> np.ndarray:
        parts = []
        for r, (d, w) in enumerate(zip(self.datasets, self.weights, strict=True)):
            n = len(d)
            whole, frac = int(math.floor(w)), w - math.floor(w)
            items = np.tile(np.arange(n), whole)
            extra = int(round(frac * n))
            if extra:
                rng = np.random.default_rng((self.seed, epoch, 3, r))
                items = np.concatenate([items, rng.choice(n, size=extra, replace=False)])
            parts.append(items + self.offsets[r])
        return np.concatenate(parts).astype(np.int64)

    def set_epoch(self, epoch: int) -> None:
        """Draw ``epoch``'s items and select its augmentation streams."""
        if epoch != self.epoch:
            self.table = self._table(epoch)
            self.epoch = epoch
        for d in self.datasets:
            d.set_epoch(epoch)

    def __len__(self) -> int:
        return len(self.table)

    def resolve(self, index: int) -> int:
        """The frame of item ``index``, as an index into the roots' concatenation."""
        return int(self.table[index])

    def locate(self, flat: int) -> tuple[int, int]:
        """``(root, frame)`` of an index into the concatenation."""
        r = int(np.searchsorted(self.offsets, flat, side="right") - 1)
        return r, flat - int(self.offsets[r])

    def __getitem__(self, index: int) -> FrameItem:
        r, i = self.locate(self.resolve(index))
        return self.datasets[r][i]


__all__ = [
    "NO_SCENE_LABELS",
    "DataSpecError",
    "MixedFrames",
    "RootSpec",
    "frame_dataset",
    "root_specs",
]
