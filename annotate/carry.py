"""Carrying a pair's boxes to the next frame of a sequence: :func:`carry_boxes`.

Annotating a 10 Hz sequence, the objects of the next frame are the objects of this one, a little
further on. Each box is moved in three steps, from the sensors only (never from a sidecar):

1. **Its own motion**: the ground velocity its radar returns tell (the mean ego-motion
   compensated radial velocity of the radar points in the box grown by
   :attr:`annotate.EvidenceConfig.radar_margin`, turned into a velocity along the box's heading by
   :func:`annotate.estimate_velocity`: road users move along their heading, and a crossing
   object, whose heading is nearly perpendicular to the line of sight, keeps only its radial
   part), times the time between the frames. A box without radar returns does not move.
2. **The ego's motion** between the two frames' poses (:func:`scenes.talk2radar.poses.lidar_motion`): the
   box is taken into the next frame's LiDAR frame (centre and heading).
3. **A refit** to the next frame's LiDAR points (:func:`annotate.fit_box`, with the box's class
   as size prior) where the radar could not tell the box's speed (no radar point in it, or a
   heading nearly perpendicular to the line of sight: :attr:`CarryConfig.refit`), kept only when
   the fitted centre is within :attr:`CarryConfig.max_refit_shift` of the moved one (a fit that
   jumped to a neighbour, or a box whose object left the view, keeps the moved box); the box
   keeps the size it had (an object does not change size between frames, and the fit of a
   partly seen object is smaller than the object), the fit giving the centre and the heading.
   Where the radar gives the speed, a refit only adds the fit's own error
   (``python -m bench.studies.carry_accuracy`` measures both).

The result is a proposal for the annotator to check and save (:class:`CarriedBox` says what each
step did). ``python -m bench.studies.carry_accuracy`` measures the centre error of carried boxes on
synthetic sequences against copying them in place (docs/ANNOTATION.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from annotate.evidence import EvidenceConfig, box_evidence, estimate_velocity
from annotate.fitting import BoxRegion, FitError, fit_box
from scenes.geometry.boxes import wrap_yaw

REFITS = ("unknown speed", "always", "never")
"""The choices of :attr:`CarryConfig.refit`."""


@dataclass(frozen=True)
class CarryConfig:
    """Parameters of :func:`carry_boxes`.

    Attributes:
        refit: Which moved boxes are refit to the next frame's LiDAR points (step 3):
            ``"unknown speed"`` (those whose speed the radar could not tell), ``"always"`` or
            ``"never"``.
        max_refit_shift: A refit whose centre lands farther than this (m, BEV) from the moved
            box is not taken.
        min_cos: ``|cos|`` between heading and line of sight below which the radar cannot tell
            the speed (:func:`annotate.estimate_velocity`'s rule).
        evidence: Margins of the radar points counted for a box's velocity.
    """

    refit: str = "unknown speed"
    max_refit_shift: float = 1.0
    min_cos: float = 0.3
    evidence: EvidenceConfig = field(default_factory=EvidenceConfig)

    def __post_init__(self) -> None:
        if self.refit not in REFITS:
            raise ValueError(f"CarryConfig: refit must be one of {REFITS}, got {self.refit!r}")
        if self.max_refit_shift < 0:
            raise ValueError(
                f"CarryConfig: max_refit_shift must be >= 0, got {self.max_refit_shift}"
            )


@dataclass(frozen=True)
class CarriedBox:
    """One box carried to the next frame.

    Attributes:
        box: ``(7,)`` the proposal, next frame's LiDAR frame.
        moved: ``(7,)`` after steps 1 and 2 (before the refit).
        velocity: ``(2,)`` ground velocity used (m/s, this frame's LiDAR axes).
        radar_points: Radar points the velocity came from (0: the box did not move by itself).
        refit: Whether the refit was taken.
    """

    box: np.ndarray
    moved: np.ndarray
    velocity: np.ndarray
    radar_points: int
    refit: bool


def move_box(box: Sequence[float], velocity: Sequence[float], dt: float, motion: np.ndarray):
    """``(7,)``: a box (this frame's LiDAR frame) after moving ``velocity * dt`` and being taken
    into the next frame's LiDAR frame by ``motion (4, 4)``."""
    b = np.asarray(box, dtype=np.float64).reshape(7).copy()
    b[:2] += np.asarray(velocity, dtype=np.float64).reshape(2) * float(dt)
    m = np.asarray(motion, dtype=np.float64).reshape(4, 4)
    b[:3] = m[:3, :3] @ b[:3] + m[:3, 3]
    b[6] = float(wrap_yaw(b[6] + np.arctan2(m[1, 0], m[0, 0])))
    return b


def carry_boxes(
    boxes: np.ndarray,
    classes: Sequence[str],
    radar: np.ndarray,
    motion: np.ndarray,
    dt: float,
    next_lidar: np.ndarray | None,
    config: CarryConfig | None = None,
) -> tuple[CarriedBox, ...]:
    """Carry ``boxes`` to the next frame (see the module docstring).

    Args:
        boxes: ``(K, 7)`` this frame's LiDAR frame.
        classes: ``K`` class names (the refit's size prior).
        radar: ``(M, 7)`` this frame's radar points, LiDAR frame (``v_r_compensated`` column 5).
        motion: ``(4, 4)`` this frame's LiDAR coordinates -> the next frame's
            (:func:`scenes.talk2radar.poses.lidar_motion`).
        dt: Seconds between the frames.
        next_lidar: ``(N, >=3)`` the next frame's LiDAR points (None: no refit).
        config: Parameters (default :class:`CarryConfig()`).

    Returns:
        ``K`` :class:`CarriedBox`, in box order.
    """
    cfg = config if config is not None else CarryConfig()
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(b) != len(classes):
        raise ValueError(f"carry_boxes: {len(b)} boxes but {len(classes)} classes")
    if not len(b):
        return ()
    evidence = box_evidence(b, np.zeros((0, 4)), radar, cfg.evidence)
    out = []
    for box, cls, ev in zip(b, classes, evidence, strict=True):
        velocity = estimate_velocity(box, ev.mean_radial_velocity, cfg.min_cos)
        moved = move_box(box, velocity, dt, motion)
        carried, refit = moved, False
        wanted = cfg.refit == "always" or (
            cfg.refit == "unknown speed" and not speed_known(box, ev.radar_points, cfg.min_cos)
        )
        if wanted and next_lidar is not None and len(next_lidar):
            fitted = _refit(moved, str(cls), next_lidar)
            if fitted is not None and np.hypot(*(fitted[:2] - moved[:2])) <= cfg.max_refit_shift:
                carried, refit = fitted, True
        out.append(CarriedBox(carried, moved, velocity, ev.radar_points, refit))
    return tuple(out)


def speed_known(box: np.ndarray, radar_points: int, min_cos: float = 0.3) -> bool:
    """Whether the radar tells a box's speed along its heading: it has radar points and its
    heading is not nearly perpendicular to the line of sight (``|cos| >= min_cos``)."""
    norm = float(np.hypot(box[0], box[1]))
    if radar_points == 0 or norm < 1e-9:
        return False
    cos_phi = (box[0] * np.cos(box[6]) + box[1] * np.sin(box[6])) / norm
    return bool(abs(cos_phi) >= min_cos)


def _refit(box: np.ndarray, cls: str, lidar: np.ndarray) -> np.ndarray | None:
    """The moved box refit to the points: the fit's centre and heading, the box's own size
    (None when the fit fails)."""
    try:
        fit = fit_box(lidar, BoxRegion(tuple(box)), cls=cls)
    except (FitError, ValueError):
        return None
    out = np.asarray(fit.box, dtype=np.float64).copy()
    out[3:6] = box[3:6]
    out[2] = fit.ground_z + box[5] / 2.0
    return out
