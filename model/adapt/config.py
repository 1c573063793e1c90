"""The settings of ``python -m model.adapt`` (:class:`AdaptConfig`, the only source of its flags)
and the curriculum they describe (:meth:`AdaptConfig.round_plan`).

Per-class thresholds on the detector's heatmap score (ST3D's triplet box partition): a box at or
above its class's *positive* threshold is a pseudo-label, a box between ``ignore_ratio`` times
that and the positive threshold is ignored (no target, no negative), anything lower is
background. The curriculum admits harder examples round by round in two ways, both linear from
the first round to the last: the positive thresholds fall from ``START`` to ``END`` (less certain
boxes), and the range within which a pseudo-label counts grows from ``--range-start`` to
``--range-end`` metres (more distant objects, seen with fewer points; beyond it a confident box is
ignored, not background).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

from scenes.geometry.classes import ALL_CLASSES, object_class
from scenes.utils.cli import add_options, from_args, option

RadarChoice = Literal["auto", "radar_5frames", "radar_3frames", "radar", "none"]
NormStatistics = Literal["keep", "follow"]
"""What the batch-norm running statistics do while adapting: ``keep`` the initial checkpoint's
(the layers in eval mode; their scale and shift still learn) or ``follow`` the new frames (train
mode, AdaBN-like)."""

DEFAULT_THRESHOLDS: dict[str, tuple[float, float]] = {
    name: pair for name in ALL_CLASSES if (pair := object_class(name).pseudo_thresholds)
}
"""Positive threshold of each class in the first and in the last round, by class name: its
:attr:`~scenes.geometry.classes.ObjectClass.pseudo_thresholds` (Car 0.5 to 0.35, Pedestrian and
Cyclist 0.4 to 0.3); ``--class-threshold`` overrides one; a class without (a nuScenes-class
checkpoint's trucks, cones...) takes ``--threshold-start`` / ``--threshold-end``."""


class AdaptError(ValueError):
    """Bad settings, root or checkpoint of an adaptation run; the message is one line that names
    the flag, file or field."""


@dataclass(frozen=True)
class RoundPlan:
    """What one round admits (the curriculum at that round).

    Attributes:
        index: The round (0 first).
        classes: The checkpoint's class names in heatmap-channel order (what a label indexes).
        positive: ``{class: threshold}``: a box scoring at least this is a pseudo-label.
        negative: ``{class: threshold}``: a box scoring at least this (and below ``positive``)
            is ignored; lower is background.
        max_range: Pseudo-labels count within this BEV distance (m) of the LiDAR; beyond it
            they are ignored.
    """

    index: int
    classes: tuple[str, ...]
    positive: dict[str, float]
    negative: dict[str, float]
    max_range: float

    def to_dict(self) -> dict[str, object]:
        return {
            "round": self.index,
            "positive": dict(self.positive),
            "negative": dict(self.negative),
            "max_range": self.max_range,
        }


@dataclass(frozen=True)
class AdaptConfig:
    """Settings of an adaptation run (``python -m model.adapt --help``)."""

    data: str = option(help="root with the sensor files of the new set-up (no labels needed)")
    init: str = option(help="checkpoint to adapt (a referent-path checkpoint)")
    out: str = option(help="run folder; given again, the run continues where it stopped")
    rounds: int = option(4, help="self-training rounds (default %(default)s)")
    steps_per_round: int = option(40, help="optimiser steps per round (default %(default)s)")
    batch_size: int = option(2, help="frames per step (default %(default)s)")
    lr: float = option(2e-4, help="peak learning rate, cosine over the run (default %(default)s)")
    weight_decay: float = option(1e-4, help="AdamW weight decay (default %(default)s)")
    grad_clip: float = option(35.0, help="gradient max-norm (default %(default)s)")
    warmup_steps: int = option(5, help="linear warm-up steps (default %(default)s)")
    threshold_start: float = option(
        0.5, help="positive threshold of an unlisted class, first round (default %(default)s)"
    )
    threshold_end: float = option(
        0.35, help="positive threshold of an unlisted class, last round (default %(default)s)"
    )
    class_threshold: tuple[str, ...] = option(
        (),
        metavar="CLASS=START[:END]",
        help="a class's positive threshold in the first (and last) round; given once per class "
        f"(defaults: {', '.join(f'{c}={a}:{b}' for c, (a, b) in DEFAULT_THRESHOLDS.items())})",
    )
    ignore_ratio: float = option(
        0.3,
        help="boxes between this share of the positive threshold and it are ignored "
        "(default %(default)s)",
    )
    range_start: float = option(30.0, help="pseudo-label range (m), first round (default 30)")
    range_end: float = option(50.0, help="pseudo-label range (m), last round (default 50)")
    seat_on_ground: bool = option(
        True,
        negatable=True,
        help="rest each new pseudo-label on the ground its LiDAR ring shows (default: on)",
    )
    regression_weight: float = option(
        0.25,
        help="weight of the box-regression loss on the pseudo-labels (the training's 0.25; 0: "
        "the heatmap alone learns, the boxes stay the initial checkpoint's) (default %(default)s)",
    )
    norm_statistics: NormStatistics = option(
        "keep",
        help="batch-norm running statistics while adapting: keep the initial checkpoint's or "
        "follow the new frames (default %(default)s)",
    )
    memory_iou: float = option(
        0.1, help="BEV IoU above which a new box and a remembered one are one object (default 0.1)"
    )
    max_miss: int = option(
        2,
        help="rounds a remembered box may go undetected (ignored meanwhile) before it is "
        "dropped (default %(default)s)",
    )
    flip_probability: float = option(0.5, help="left-right flip probability (default 0.5)")
    max_rotation: float = option(
        0.3927, help="largest rotation about z (rad, uniform +-; default pi/8)"
    )
    scale_range: tuple[float, float] = option(
        (0.95, 1.05), metavar=("LOW", "HIGH"), help="uniform global scaling (default 0.95 1.05)"
    )
    max_frames: int = option(0, help="use the first N frames only (0: all)")
    split: str = option(
        "", help="ImageSets list to adapt on (default: every frame of the LiDAR folder)"
    )
    radar_folder: RadarChoice = option("auto", help="radar tree")
    seed: int = option(0, help="seed of the data order and augmentations (default 0)")
    device: str = option("cpu", help="cpu or cuda")
    stop_after_round: int = option(
        0, on_resume=True, help="stop (resumable) after this many rounds (0: run them all)"
    )
    quiet: bool = option(False, on_resume=True, help="no progress bar")
    overrides: dict[str, tuple[float, float]] = field(default_factory=dict, metadata={"cli": False})
    """Filled from ``class_threshold``: ``{class: (start, end)}``."""

    def __post_init__(self) -> None:
        for name, value in (("rounds", self.rounds), ("steps-per-round", self.steps_per_round)):
            if value < 1:
                raise AdaptError(f"--{name} must be at least 1, got {value}")
        if self.batch_size < 1:
            raise AdaptError(f"--batch-size must be at least 1, got {self.batch_size}")
        for name, value in (
            ("threshold-start", self.threshold_start),
            ("threshold-end", self.threshold_end),
            ("ignore-ratio", self.ignore_ratio),
            ("flip-probability", self.flip_probability),
            ("regression-weight", self.regression_weight),
        ):
            if not 0.0 <= value <= 1.0:
                raise AdaptError(f"--{name} must be in [0, 1], got {value}")
        if not 0.0 < self.range_start <= self.range_end:
            raise AdaptError(
                f"--range-start ({self.range_start}) must be positive and at most --range-end "
                f"({self.range_end})"
            )
        low, high = self.scale_range
        if not 0.0 < low <= high:
            raise AdaptError(f"--scale-range must be 0 < LOW <= HIGH, got {low} {high}")
        if self.max_miss < 0 or self.max_frames < 0 or self.stop_after_round < 0:
            raise AdaptError("--max-miss, --max-frames and --stop-after-round must be >= 0")
        object.__setattr__(self, "overrides", self._overrides())

    def _overrides(self) -> dict[str, tuple[float, float]]:
        out = {}
        for given in self.class_threshold:
            name, sep, values = given.partition("=")
            if not sep or name not in ALL_CLASSES:
                raise AdaptError(
                    f"--class-threshold {given!r}: expected CLASS=START[:END] with CLASS one of "
                    f"{', '.join(ALL_CLASSES)}"
                )
            try:
                parts = [float(v) for v in values.split(":")]
            except ValueError:
                raise AdaptError(
                    f"--class-threshold {given!r}: thresholds must be numbers"
                ) from None
            if len(parts) not in (1, 2) or not all(0.0 < v < 1.0 for v in parts):
                raise AdaptError(
                    f"--class-threshold {given!r}: one or two thresholds in (0, 1) expected"
                )
            out[name] = (parts[0], parts[-1])
        return out

    def thresholds(self, classes: Sequence[str]) -> dict[str, tuple[float, float]]:
        """``{class: (first round's, last round's)}`` positive threshold of each of the
        checkpoint's ``classes``: ``--class-threshold``, else :data:`DEFAULT_THRESHOLDS`, else
        ``--threshold-start`` / ``--threshold-end``. AdaptError naming the flag when an override
        names a class the checkpoint does not have."""
        for name in self.overrides:
            if name not in classes:
                raise AdaptError(
                    f"--class-threshold {name}=...: the checkpoint's classes are "
                    f"{', '.join(classes)}"
                )
        default = (self.threshold_start, self.threshold_end)
        return {c: self.overrides.get(c, DEFAULT_THRESHOLDS.get(c, default)) for c in classes}

    def round_plan(self, index: int, classes: Sequence[str]) -> RoundPlan:
        """The curriculum at round ``index`` (module docstring) for a checkpoint of ``classes``
        (heatmap-channel order): thresholds and range linear from the first round's to the
        last's."""
        t = index / (self.rounds - 1) if self.rounds > 1 else 1.0
        positive = {c: a + (b - a) * t for c, (a, b) in self.thresholds(classes).items()}
        negative = {c: v * self.ignore_ratio for c, v in positive.items()}
        max_range = self.range_start + (self.range_end - self.range_start) * t
        return RoundPlan(index, tuple(classes), positive, negative, max_range)

    def settings(self) -> dict[str, object]:
        """The settings a resumed run must share (every flag but the ``on_resume`` ones), as
        plain data."""
        free = {"stop_after_round", "quiet", "overrides"}
        out: dict[str, object] = {}
        for name in self.__dataclass_fields__:
            if name not in free:
                value = getattr(self, name)
                out[name] = list(value) if isinstance(value, tuple) else value
        return out


def build_parser() -> argparse.ArgumentParser:
    """``python -m model.adapt``'s parser (flags from :class:`AdaptConfig`)."""
    parser = argparse.ArgumentParser(
        prog="python -m model.adapt",
        description="Adapt a checkpoint's detector to a new sensor set-up by self-training on "
        "unlabelled frames (ST3D): per-class pseudo-label thresholds, a memory of pseudo-labels "
        "across rounds, augmentation consistency and a curriculum.",
    )
    add_options(parser, AdaptConfig)
    return parser


def parse_args(argv: list[str] | None = None) -> AdaptConfig:
    """The command line as an :class:`AdaptConfig` (:class:`AdaptError` on bad values)."""
    return from_args(AdaptConfig, build_parser().parse_args(argv))


__all__ = [
    "DEFAULT_THRESHOLDS",
    "AdaptConfig",
    "AdaptError",
    "NormStatistics",
    "RoundPlan",
    "build_parser",
    "parse_args",
]
