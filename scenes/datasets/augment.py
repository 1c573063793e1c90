"""Training augmentations: the left-right flip, and sensor augmentations (issue 14, sim-to-real).

The flip, the one home of it: whether an item is flipped (:meth:`AugmentConfig.draws_flip`,
:func:`draw_flip`: the first draw of the item's stream, :func:`item_rng`) and how
(:func:`flip_sample` for :class:`scenes.datasets.grounding.GroundingDataset`, :func:`flip_frame` for
:class:`scenes.datasets.frames.FrameDataset`; the ``--freeze-scene`` training draws its mirrored
views with :func:`draw_flip` too). It mirrors a scene about the LiDAR's x-z plane: ``y -> -y``, ``yaw -> -yaw``, a ground velocity's
``vy -> -vy``, and "left" and "right" swapped in the prompt
(:func:`scenes.language.prompts.flip_left_right`). Radar radial velocities are unchanged: the radar sits on
the LiDAR's x axis, so the mirror keeps every range and line of sight.

The sensor augmentations make a model robust to what still differs between the synthetic sensors and the real ones
(intensity calibration, point density, radar point count and RCS level) and turn an accumulated
radar cloud into the single scan that real roots often ship (the ``radar`` tree).

Conventions
    LiDAR points: ``(N, 4)`` float32 ``x, y, z, intensity`` (0..255) in the LiDAR frame.
    Radar points: ``(M, 7)`` float32 ``x, y, z, rcs, v_r, v_r_compensated, time`` in the LiDAR
    frame (``time`` = 0 for the newest scan, -1, -2, ... for older ones).
    Every function takes its randomness from an explicit :class:`numpy.random.Generator`, never
    modifies its input, returns a new float32 array of the same number of columns, and raises a
    ValueError naming the argument for a bad shape or parameter.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from scenes.geometry.actors import Actor
from scenes.geometry.boxes import wrap_yaw
from scenes.language.prompts import flip_left_right
from scenes.synth.lidar import LidarConfig, beam_elevations

LIDAR_COLUMNS = 4
RADAR_COLUMNS = 7
RCS_COLUMN = 3
TIME_COLUMN = 6
DEFAULT_LIDAR = LidarConfig()
"""The generator's LiDAR (View-of-Delft's HDL-64 layout), whose beams :func:`drop_beams` drops."""


def _check(points: np.ndarray, columns: int, name: str) -> np.ndarray:
    arr = np.asarray(points)
    if arr.ndim != 2 or arr.shape[1] != columns:
        raise ValueError(f"{name}: expected an (N, {columns}) array, got shape {arr.shape}")
    return arr


def _check_range(bounds: tuple[float, float], name: str, lo: float, hi: float) -> None:
    a, b = bounds
    if not lo <= a <= b <= hi:
        raise ValueError(f"{name}: expected {lo} <= low <= high <= {hi}, got {bounds}")


def item_rng(seed: int, epoch: int, index: int) -> np.random.Generator:
    """The augmentation stream of item ``index`` at ``epoch``, seeded by ``(seed, epoch, index)``
    (runs and resumed runs repeat exactly)."""
    return np.random.default_rng((seed, epoch, index))


def draw_flip(rng: np.random.Generator, probability: float) -> bool:
    """Whether to flip: one uniform draw of ``rng`` below ``probability`` (drawn whatever the
    probability, so the draws after it do not depend on it)."""
    return bool(rng.random() < probability)


@dataclass(frozen=True)
class AugmentConfig:
    """Train-time augmentations.

    Attributes:
        flip_probability: Probability of the left-right flip.
        lidar_keep_min: Each item keeps a uniform fraction in ``[lidar_keep_min, 1]`` of its LiDAR
            points (1.0 disables the dropout).
        shuffle_points: Shuffle the point order.
    """

    flip_probability: float = 0.5
    lidar_keep_min: float = 0.8
    shuffle_points: bool = True

    def draws_flip(self, rng: np.random.Generator) -> bool:
        """Whether an item is flipped left-right: :func:`draw_flip` with
        :attr:`flip_probability` (the first draw of the item's stream)."""
        return draw_flip(rng, self.flip_probability)

    def thin_and_shuffle(
        self, lidar: np.ndarray, radar: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """The LiDAR dropout and the point shuffling (after the flip): ``(N, 4)``, ``(M, 7)``."""
        if self.lidar_keep_min < 1.0 and len(lidar):
            keep = rng.uniform(self.lidar_keep_min, 1.0)
            lidar = lidar[rng.random(len(lidar)) < keep]
        if self.shuffle_points:
            lidar = lidar[rng.permutation(len(lidar))]
            radar = radar[rng.permutation(len(radar))]
        return lidar, radar

    def __post_init__(self) -> None:
        if not 0.0 <= self.flip_probability <= 1.0:
            raise ValueError(f"flip_probability must be in [0, 1], got {self.flip_probability}")
        if not 0.0 < self.lidar_keep_min <= 1.0:
            raise ValueError(f"lidar_keep_min must be in (0, 1], got {self.lidar_keep_min}")


def mirror_points(points: np.ndarray) -> np.ndarray:
    """A copy of ``(N, C)`` points (any sensor, LiDAR frame, ``C >= 2``) with ``y`` negated; the
    dtype is kept."""
    out = np.array(points, copy=True)
    out[:, 1] *= -1
    return out


def mirror_boxes(boxes: np.ndarray) -> np.ndarray:
    """``(K, 7)`` float64 copy of LiDAR-frame boxes (or one ``(7,)`` box) mirrored: ``y`` and
    ``yaw`` negated, ``yaw`` wrapped to ``[-pi, pi)``."""
    out = np.array(boxes, dtype=np.float64, copy=True).reshape(-1, 7)
    out[:, 1] *= -1
    out[:, 6] = wrap_yaw(-out[:, 6])
    return out


def mirror_actor(actor: Actor) -> Actor:
    """The actor mirrored about the LiDAR's x-z plane (box as :func:`mirror_boxes`, ``vy``
    negated)."""
    vel = actor.velocity * np.array([1.0, -1.0])
    return Actor(actor.actor_id, actor.cls, mirror_boxes(actor.box)[0], vel)


def flip_sample(
    lidar: np.ndarray, radar: np.ndarray, boxes: np.ndarray, prompt: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Mirror a sample about the LiDAR's x-z plane and swap left/right in the prompt.

    Args:
        lidar: ``(N, 4)``; radar: ``(M, 7)``; boxes: ``(K, 7)``; all LiDAR frame.

    Returns:
        The mirrored copies (boxes ``(K, 7)`` float64) and the rewritten prompt.
    """
    return mirror_points(lidar), mirror_points(radar), mirror_boxes(boxes), flip_left_right(prompt)


def flip_frame(
    lidar: np.ndarray, radar: np.ndarray, actors: Sequence[Actor], texts: Sequence[str]
) -> tuple[np.ndarray, np.ndarray, tuple[Actor, ...], tuple[str, ...]]:
    """Mirror a frame about the LiDAR's x-z plane and swap left/right in its sentences.

    Args:
        lidar: ``(N, 4)``; radar: ``(M, 7)``; actors: LiDAR frame; texts: sentences about it.

    Returns:
        The mirrored points, the mirrored actors (:func:`mirror_actor`) and the rewritten texts.
    """
    mirrored = tuple(mirror_actor(a) for a in actors)
    flipped = tuple(flip_left_right(t) for t in texts)
    return mirror_points(lidar), mirror_points(radar), mirrored, flipped


def jitter_intensity(
    points: np.ndarray,
    rng: np.random.Generator,
    scale: tuple[float, float] = (0.7, 1.3),
    offset: tuple[float, float] = (-20.0, 20.0),
) -> np.ndarray:
    """One random gain and offset for the whole cloud's intensity, clipped to ``[0, 255]``.

    Args:
        points: ``(N, 4)`` LiDAR points.
        scale: Range of the uniform gain.
        offset: Range of the uniform offset (intensity units).

    Returns:
        ``(N, 4)`` float32: ``intensity * gain + offset``, clipped; x, y, z unchanged.
    """
    arr = _check(points, LIDAR_COLUMNS, "points")
    _check_range(scale, "scale", 0.0, np.inf)
    _check_range(offset, "offset", -255.0, 255.0)
    gain, shift = rng.uniform(*scale), rng.uniform(*offset)
    out = arr.astype(np.float32, copy=True)
    out[:, 3] = np.clip(out[:, 3] * gain + shift, 0.0, 255.0)
    return out


def drop_points(points: np.ndarray, rng: np.random.Generator, rate: float) -> np.ndarray:
    """Random point dropout: each point (row) is removed independently with probability ``rate``.

    Args:
        points: ``(N, C)`` points of any sensor (LiDAR ``C = 4``, radar ``C = 7``).
        rate: Probability in ``[0, 1]`` that a point is removed.

    Returns:
        ``(K, C)`` float32, the kept rows in their original order.
    """
    arr = np.asarray(points)
    if arr.ndim != 2:
        raise ValueError(f"points: expected an (N, C) array, got shape {arr.shape}")
    if not 0.0 <= rate <= 1.0:
        raise ValueError(f"rate: expected a probability in [0, 1], got {rate}")
    keep = rng.random(len(arr)) >= rate
    return arr[keep].astype(np.float32)


def beam_index(points: np.ndarray, config: LidarConfig = DEFAULT_LIDAR) -> np.ndarray:
    """``(N,)`` int: the beam (0 = top) whose elevation is nearest to each point's elevation seen
    from the LiDAR origin. ``points``: ``(N, >=3)`` in the LiDAR frame."""
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] < 3:
        raise ValueError(f"points: expected an (N, >=3) array, got shape {arr.shape}")
    elevation = np.degrees(np.arctan2(arr[:, 2], np.hypot(arr[:, 0], arr[:, 1])))
    beams = beam_elevations(config)  # descending
    order = np.argsort(beams)
    ascending = beams[order]
    pos = np.clip(np.searchsorted(ascending, elevation), 1, len(ascending) - 1)
    nearer_low = elevation - ascending[pos - 1] < ascending[pos] - elevation
    return order[np.where(nearer_low, pos - 1, pos)]


def drop_beams(
    points: np.ndarray,
    rng: np.random.Generator,
    rate: float,
    config: LidarConfig = DEFAULT_LIDAR,
) -> np.ndarray:
    """Beam-wise LiDAR dropout: each of the sensor's beams is removed with probability ``rate``
    (all its points), as a sparser sensor or dead lasers.

    Args:
        points: ``(N, 4)`` LiDAR points (LiDAR frame; beams assigned by :func:`beam_index`).
        rate: Probability in ``[0, 1]`` that a beam is removed.
        config: The LiDAR whose beam layout is used.

    Returns:
        ``(K, 4)`` float32, the points of the kept beams in their original order.
    """
    arr = _check(points, LIDAR_COLUMNS, "points")
    if not 0.0 <= rate <= 1.0:
        raise ValueError(f"rate: expected a probability in [0, 1], got {rate}")
    dropped = rng.random(2 * config.beams_per_block) < rate
    return arr[~dropped[beam_index(arr, config)]].astype(np.float32)


def subsample_radar(
    points: np.ndarray, rng: np.random.Generator, keep: tuple[float, float] = (0.5, 1.0)
) -> np.ndarray:
    """Radar point-count dropout: keep a uniformly drawn fraction of the points, chosen at random
    without replacement (at least one point when the input has any).

    Args:
        points: ``(M, 7)`` radar points.
        keep: Range of the kept fraction, within ``[0, 1]``.

    Returns:
        ``(K, 7)`` float32, the kept rows in their original order.
    """
    arr = _check(points, RADAR_COLUMNS, "points")
    _check_range(keep, "keep", 0.0, 1.0)
    if len(arr) == 0:
        return arr.astype(np.float32)
    count = max(1, int(round(rng.uniform(*keep) * len(arr))))
    chosen = np.sort(rng.choice(len(arr), size=count, replace=False))
    return arr[chosen].astype(np.float32)


def jitter_rcs(
    points: np.ndarray,
    rng: np.random.Generator,
    offset_db: tuple[float, float] = (-3.0, 3.0),
    noise_db: float = 0.0,
) -> np.ndarray:
    """A common RCS offset (dB) for the whole radar cloud, plus optional per-point Gaussian noise.

    Args:
        points: ``(M, 7)`` radar points.
        offset_db: Range of the uniform common offset.
        noise_db: Standard deviation of the per-point noise (>= 0).

    Returns:
        ``(M, 7)`` float32 with column 3 (RCS, dBsm) shifted; other columns unchanged.
    """
    arr = _check(points, RADAR_COLUMNS, "points")
    _check_range(offset_db, "offset_db", -np.inf, np.inf)
    if noise_db < 0:
        raise ValueError(f"noise_db: expected >= 0, got {noise_db}")
    out = arr.astype(np.float32, copy=True)
    shift = rng.uniform(*offset_db)
    out[:, RCS_COLUMN] += shift + rng.normal(0.0, noise_db, len(out))
    return out


def single_scan(points: np.ndarray) -> np.ndarray:
    """The newest scan of an accumulated radar cloud: the rows with ``time == 0``.

    Args:
        points: ``(M, 7)`` radar points (e.g. a ``radar_5frames`` cloud).

    Returns:
        ``(K, 7)`` float32, as the single-scan ``radar`` tree of a real root.
    """
    arr = _check(points, RADAR_COLUMNS, "points")
    return arr[arr[:, TIME_COLUMN] == 0].astype(np.float32)
