"""Fit a box's centre, size and yaw to the LiDAR points of a selected region.

Steps of :func:`fit_box` (all in the LiDAR frame):

1. Selection: the points whose bird's-eye-view position lies in the region, a rough box (a vertical
   prism, its ``z`` extent ignored, grown by ``margin``) or a disk (centre + radius). The box's own
   height is ignored on purpose: a box placed by a ground click has a default height that may cut
   the object's top.
2. Ground: ``ground_z`` when given, else the local ground (:mod:`scenes.geometry.ground`) of the
   region grown by ``ground_margin``, its own points included (the object may overhang a rough
   region). Points at most ``ground_clearance`` above the ground, or more than ``max_height``
   above it, are left out.
3. Clustering (``cluster_gap``): the points are split into groups whose BEV gaps exceed the gap
   (connected components of a grid of ``cluster_gap`` cells, 8-neighbourhood); the largest group is
   kept, so a kerb or a neighbour's edge caught by a generous region does not inflate the box.
4. Rectangle: the minimum-area rectangle enclosing the BEV convex hull (Andrew's monotone chain).
   One side of a minimum-area enclosing rectangle is collinear with a hull edge, so trying each
   hull edge's direction (the rotating-calipers candidates, evaluated at once with NumPy) finds it.
   Near-ties (an L-shaped scan of two sides) go to the rectangle whose edges the points hug.
5. Class prior (:func:`complete_rectangle`; only with ``cls``, a class whose typical size is its
   ``ObjectClass.mean_size`` and with a minimum in ``FitConfig.class_min_sizes``): an object
   seen from one side shows one face, a thin slab. When the rectangle is below the class's minimum
   along a side, the hidden part is completed. (a) Orientation: when the short side is under
   ``degenerate_fraction`` of the typical width, the long side is a face: the object's length (a
   car's side) or its width (a car's rear, a cyclist head-on), whichever typical size it is nearer
   to in ratio (log); its width only if at most ``1 + width_tolerance`` times the typical width.
   For a car (4.2 x 1.8 m) a face of at most 2.16 m (the ratio alone: sqrt(4.2 * 1.8) = 2.75 m) is
   its width; the length then runs across it. (b) Size: each side below the minimum grows to it
   AWAY from the sensor (the LiDAR origin): the side's end nearer the sensor, what was seen, stays
   at the points (a side with the sensor between its ends grows about its middle). A side the points show at
   least the minimum long is kept (never inflated). Without ``cls``: skipped.
6. Orientation: the length runs along the rectangle's length axis (the longer side, unless step 5
   turned it); of the two headings along it, the one nearer ``prior_yaw`` is kept (default: the
   rough box's yaw, or 0 = facing away from the ego vehicle for a disk). Points cannot tell an
   object's front from its back.
7. Height: from the ground (``extend_to_ground``, objects stand on the ground; else from the lowest
   kept point) to the highest kept point. Sizes are at least ``min_size``.

Too few points after these steps raise :class:`FitError` with the count and what to change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenes.geometry.boxes import points_in_boxes, wrap_yaw
from scenes.geometry.classes import ALL_CLASSES, object_class
from scenes.geometry.ground import ground_around, ground_under_boxes


class FitError(ValueError):
    """The region holds too few usable points to fit a box; the message says how many."""


@dataclass(frozen=True)
class BoxRegion:
    """A rough box ``(7,)`` (LiDAR frame); its BEV footprint grown by ``margin`` metres per side."""

    box: tuple[float, ...]
    margin: float = 0.3

    def __post_init__(self) -> None:
        b = np.asarray(self.box, dtype=np.float64).reshape(-1)
        if b.shape != (7,) or not np.all(np.isfinite(b)):
            raise ValueError(f"BoxRegion: expected 7 finite values, got {self.box!r}")
        if np.any(b[3:5] <= 0):
            raise ValueError(f"BoxRegion: length and width must be positive, got {b[3:5]}")
        if self.margin < 0:
            raise ValueError(f"BoxRegion: margin must be >= 0, got {self.margin}")
        object.__setattr__(self, "box", tuple(float(v) for v in b))


@dataclass(frozen=True)
class DiskRegion:
    """A vertical cylinder: BEV ``centre (x, y)`` and ``radius`` in metres, LiDAR frame."""

    centre: tuple[float, float]
    radius: float

    def __post_init__(self) -> None:
        c = tuple(float(v) for v in self.centre)
        if len(c) != 2 or not all(np.isfinite(c)):
            raise ValueError(f"DiskRegion: centre must be two finite numbers, got {self.centre!r}")
        if not self.radius > 0:
            raise ValueError(f"DiskRegion: radius must be positive, got {self.radius}")
        object.__setattr__(self, "centre", c)


Region = BoxRegion | DiskRegion


CLASS_MIN_SIZES: tuple[tuple[str, float, float], ...] = tuple(
    (n, *f) for n in ALL_CLASSES if (f := object_class(n).min_footprint) is not None
)
"""``(class, min_length, min_width)`` of every class with a ``min_footprint`` (m)."""


@dataclass(frozen=True)
class FitConfig:
    """Parameters of :func:`fit_box` (see the module docstring).

    Attributes:
        ground_margin: BEV growth of the region (m) for the ground estimate.
        ground_clearance: Points up to this height above the ground (m) count as ground.
        max_height: Points higher than this above the ground (m) are left out (branches, signs).
        cluster_gap: BEV gap (m) that separates two objects; None keeps every point.
        min_points: Fewest points a fit needs.
        min_size: Smallest length, width and height of a fitted box (m).
        extend_to_ground: Let the box reach down to the ground.
        class_min_sizes: ``(class, min_length, min_width)``, metres: the plausible minimum BEV
            size per class, below which a fit with ``cls`` completes the hidden part (step 5);
            default: every class's :attr:`~scenes.geometry.classes.ObjectClass.min_footprint`
            (Car 3.5 x 1.5, Pedestrian 0.4 x 0.4, Cyclist 1.5 x 0.5; typical sizes: the
            classes' ``mean_size``).
        degenerate_fraction: A short side under this fraction of the class's typical width means
            one face was seen; its orientation then follows the typical length and width.
        width_tolerance: That face is the object's width only if at most ``1 + width_tolerance``
            times the typical width (a cyclist's 1 m side is not its 0.7 m width).
        grow_to_typical: Grow a side below the minimum to the typical size (clicked-and-fitted
            cars of the default data: median centre error 0.09 m, 0.26 m at the minimum only).
    """

    ground_margin: float = 2.0
    ground_clearance: float = 0.2
    max_height: float = 4.0
    cluster_gap: float | None = 0.5
    min_points: int = 5
    min_size: float = 0.1
    extend_to_ground: bool = True
    class_min_sizes: tuple[tuple[str, float, float], ...] = CLASS_MIN_SIZES
    degenerate_fraction: float = 0.6
    width_tolerance: float = 0.2
    grow_to_typical: bool = True

    def __post_init__(self) -> None:
        if self.cluster_gap is not None and self.cluster_gap <= 0:
            raise ValueError(f"FitConfig: cluster_gap must be positive, got {self.cluster_gap}")
        if self.min_points < 1 or self.min_size <= 0 or self.max_height <= 0:
            raise ValueError("FitConfig: min_points, min_size and max_height must be positive")
        if not 0.0 < self.degenerate_fraction <= 1.0:
            raise ValueError(
                f"FitConfig: degenerate_fraction {self.degenerate_fraction} not in (0, 1]"
            )
        if not self.width_tolerance >= 0.0:
            raise ValueError(f"FitConfig: width_tolerance must be >= 0, got {self.width_tolerance}")
        names = [entry[0] if len(entry) == 3 else None for entry in self.class_min_sizes]
        for k, entry in enumerate(self.class_min_sizes):
            sizes = entry[1:] if len(entry) == 3 else ()
            if not isinstance(names[k], str) or not all(
                isinstance(v, int | float) and math.isfinite(v) and v > 0 for v in sizes
            ):
                raise ValueError(
                    f"FitConfig: class_min_sizes[{k}] must be (class, min_length > 0, "
                    f"min_width > 0), got {entry!r}"
                )
            if names[k] in names[:k]:
                raise ValueError(f"FitConfig: class_min_sizes[{k}]: class {names[k]!r} repeated")

    def class_minimum(self, cls: str) -> tuple[float, float] | None:
        """The plausible minimum ``(length, width)`` of ``cls`` in metres, or None if unknown."""
        sizes = {
            name: (float(length), float(width)) for name, length, width in self.class_min_sizes
        }
        return sizes.get(cls)


@dataclass(frozen=True)
class FitResult:
    """A fitted box.

    Attributes:
        box: ``(7,)`` float64 ``x, y, z, l, w, h, yaw``, LiDAR frame.
        num_points: Points the rectangle was fitted to.
        ground_z: Ground height used (m).
        used: ``(N,)`` bool mask over the input points: the points the box was fitted to.
        completed: The class prior grew or turned the rectangle the points show (step 5).
    """

    box: np.ndarray
    num_points: int
    ground_z: float
    used: np.ndarray
    completed: bool = False


@dataclass(frozen=True)
class Rectangle:
    """A BEV rectangle: ``centre (2,)``, ``length``, ``width`` and ``yaw`` of the length axis.

    :func:`min_area_rectangle` returns ``length >= width``; :func:`complete_rectangle` returns the
    object's length along ``yaw`` (at least the width in the ``mean_size`` of every class with
    a ``min_footprint``).
    """

    centre: np.ndarray
    length: float
    width: float
    yaw: float


def convex_hull(xy: np.ndarray) -> np.ndarray:
    """Convex hull of ``(N, 2)`` points, counter-clockwise, without repeated or collinear points.

    Returns ``(H, 2)``; ``H`` is 1 or 2 for coincident or collinear input.
    """
    pts = np.unique(np.asarray(xy, dtype=np.float64).reshape(-1, 2), axis=0)  # sorted by x, y
    if len(pts) <= 2:
        return pts

    def half(points: np.ndarray) -> list[np.ndarray]:
        chain: list[np.ndarray] = []
        for p in points:
            while len(chain) >= 2:
                o, a = chain[-2], chain[-1]
                cross = (a[0] - o[0]) * (p[1] - o[1]) - (a[1] - o[1]) * (p[0] - o[0])
                if cross > 1e-12:
                    break
                chain.pop()
            chain.append(p)
        return chain

    lower = half(pts)
    upper = half(pts[::-1])
    hull = np.array(lower[:-1] + upper[:-1])
    return hull


def min_area_rectangle(
    xy: np.ndarray, min_size: float = 0.0, tie_tolerance: float = 0.05
) -> Rectangle:
    """The minimum-area rectangle enclosing ``(N, 2)`` points (N >= 1), BEV.

    Candidate directions are the hull edges'. Among the candidates whose area is within
    ``tie_tolerance`` (relative) of the smallest, the one whose edges the points hug most closely
    (mean distance of every point to its nearest edge) wins: an L-shaped scan (two sides of a car
    seen from a corner) has a leg-aligned and a hypotenuse-aligned rectangle of the same area, and
    only the first has the points on its edges.

    The length is the longer side; ``yaw`` is the direction of the length axis in
    ``[-pi/2, pi/2)`` (either heading along it encloses the same points). Sides shorter than
    ``min_size`` are widened to it about the centre.
    """
    pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    hull = convex_hull(pts)
    if len(hull) == 0:
        raise FitError("no points to fit a rectangle to")
    if len(hull) == 1:
        angles = np.zeros(1)
    else:
        edges = np.roll(hull, -1, axis=0) - hull
        if len(hull) == 2:
            edges = edges[:1]
        angles = np.arctan2(edges[:, 1], edges[:, 0])
    cos, sin = np.cos(angles), np.sin(angles)
    # Coordinates of every hull point along (u) and across (v) every candidate direction: (E, H).
    u = hull[None, :, 0] * cos[:, None] + hull[None, :, 1] * sin[:, None]
    v = -hull[None, :, 0] * sin[:, None] + hull[None, :, 1] * cos[:, None]
    u_min, u_max, v_min, v_max = u.min(1), u.max(1), v.min(1), v.max(1)
    area = (u_max - u_min) * (v_max - v_min)
    near = np.nonzero(area <= area.min() * (1.0 + tie_tolerance) + 1e-12)[0]
    if len(near) > 1:
        pu = pts[None, :, 0] * cos[near, None] + pts[None, :, 1] * sin[near, None]
        pv = -pts[None, :, 0] * sin[near, None] + pts[None, :, 1] * cos[near, None]
        gap = np.minimum(
            np.minimum(pu - u_min[near, None], u_max[near, None] - pu),
            np.minimum(pv - v_min[near, None], v_max[near, None] - pv),
        )
        best = int(near[np.argmin(gap.mean(axis=1))])
    else:
        best = int(near[0])
    mid_u = 0.5 * (u_max[best] + u_min[best])
    mid_v = 0.5 * (v_max[best] + v_min[best])
    c, s = cos[best], sin[best]
    centre = np.array([mid_u * c - mid_v * s, mid_u * s + mid_v * c])
    length = float(u_max[best] - u_min[best])
    width = float(v_max[best] - v_min[best])
    yaw = float(angles[best])
    if width > length:
        length, width, yaw = width, length, yaw + np.pi / 2.0
    return _at_least(Rectangle(centre, length, width, _half_turn(yaw)), min_size)


def _at_least(rect: Rectangle, min_size: float) -> Rectangle:
    """``rect`` with sides shorter than ``min_size`` widened to it about the centre."""
    return Rectangle(rect.centre, max(rect.length, min_size), max(rect.width, min_size), rect.yaw)


def _half_turn(yaw: float) -> float:
    """``yaw`` as an axis direction in ``[-pi/2, pi/2)`` (a heading and its opposite are one)."""
    yaw = float(wrap_yaw(yaw))
    if yaw >= np.pi / 2.0 - 1e-12:
        yaw -= np.pi
    elif yaw < -np.pi / 2.0:
        yaw += np.pi
    return yaw


def _grown_offset(size: float, target: float, sensor: float) -> float:
    """Shift of a side's middle as it grows from ``size`` to ``target`` away from ``sensor`` (the
    sensor's coordinate along the side, relative to its middle)."""
    if target <= size:
        return 0.0
    half = size / 2.0
    if sensor <= -half:  # the sensor is before the low end: keep it, grow the high end
        return target / 2.0 - half
    if sensor >= half:
        return half - target / 2.0
    return 0.0  # the sensor is between the ends: grow about the middle


def complete_rectangle(
    rect: Rectangle,
    typical: tuple[float, float],
    minimum: tuple[float, float],
    config: FitConfig,
    *,
    sensor: tuple[float, float] = (0.0, 0.0),
) -> tuple[Rectangle, bool]:
    """Complete the hidden part of an object seen from one side (module docstring, step 5).

    Args:
        rect: The rectangle the points show (``length >= width >= 0``, ``length > 0``), BEV.
        typical: The class's typical ``(length, width)`` in metres.
        minimum: The class's plausible minimum ``(length, width)`` in metres.
        config: Its ``degenerate_fraction``, ``width_tolerance`` and ``grow_to_typical``.
        sensor: The sensor's BEV position (the LiDAR origin).

    Returns:
        The completed rectangle (its ``length`` along ``yaw`` in ``[-pi/2, pi/2)``, the object's
        length axis) and whether it differs from ``rect``; ``rect`` itself when it is at least the
        minimum along both sides. The result encloses ``rect``, and a side's end nearer the sensor
        stays where it was.
    """
    length_t, width_t = typical
    min_length, min_width = minimum
    if not (rect.length >= rect.width >= 0 and rect.length > 0 and min(typical) > 0):
        raise ValueError(
            f"complete_rectangle: need length > 0, width >= 0 and a positive typical size, got "
            f"{rect.length} x {rect.width} m and {typical}"
        )
    if rect.length >= min_length and rect.width >= min_width:
        return rect, False
    face = rect.length
    # The long side is the face seen; is it the object's width (the length runs across it)?
    swap = (
        rect.width < config.degenerate_fraction * width_t
        and face <= width_t * (1.0 + config.width_tolerance)
        and abs(math.log(face / width_t)) < abs(math.log(face / length_t))
    )
    yaw = rect.yaw + math.pi / 2.0 if swap else rect.yaw
    along, across = (rect.width, rect.length) if swap else (rect.length, rect.width)
    goal = (length_t, width_t) if config.grow_to_typical else (min_length, min_width)
    goal_length, goal_width = goal
    new_along = max(along, goal_length) if along < min_length else along
    new_across = max(across, goal_width) if across < min_width else across
    c, s = math.cos(yaw), math.sin(yaw)
    to_sensor = np.asarray(sensor, dtype=np.float64) - rect.centre
    du = _grown_offset(along, new_along, float(to_sensor[0] * c + to_sensor[1] * s))
    dv = _grown_offset(across, new_across, float(-to_sensor[0] * s + to_sensor[1] * c))
    centre = rect.centre + np.array([du * c - dv * s, du * s + dv * c])
    return Rectangle(centre, new_along, new_across, _half_turn(yaw)), True


def _local_ground(points: np.ndarray, region: Region, grow: float) -> float:
    """The local ground (m) of ``region`` grown by ``grow``, its own points included."""
    if isinstance(region, DiskRegion):
        return ground_around(points, np.asarray(region.centre), region.radius + grow, min_points=1)
    ring = region.margin + grow
    return float(ground_under_boxes(points, region.box, ring, with_footprint=True, min_points=1)[0])


def _in_region(xy: np.ndarray, region: Region, grow: float = 0.0) -> np.ndarray:
    if isinstance(region, DiskRegion):
        d = xy - np.asarray(region.centre)
        return np.hypot(d[:, 0], d[:, 1]) <= region.radius + grow
    b = np.array(region.box, dtype=np.float64)
    b[3:5] += 2.0 * (region.margin + grow)
    b[2], b[5] = 0.0, 1.0
    flat = np.c_[xy, np.zeros(len(xy))]
    return points_in_boxes(flat, b[None])[:, 0]


def _largest_cluster(xy: np.ndarray, gap: float) -> np.ndarray:
    """Mask ``(N,)`` of the largest group of points connected through BEV cells of size ``gap``."""
    cells = np.floor(xy / gap).astype(np.int64)
    uniq, inverse = np.unique(cells, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    index = {(int(a), int(b)): i for i, (a, b) in enumerate(uniq)}
    parent = list(range(len(uniq)))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, (a, b) in enumerate(uniq):
        for da in (-1, 0, 1):
            for db in (-1, 0, 1):
                j = index.get((int(a) + da, int(b) + db))
                if j is not None:
                    ri, rj = find(i), find(j)
                    if ri != rj:
                        parent[rj] = ri
    roots = np.array([find(i) for i in range(len(uniq))])
    point_root = roots[inverse]
    labels, counts = np.unique(point_root, return_counts=True)
    return point_root == labels[int(np.argmax(counts))]


def fit_box(
    points: np.ndarray,
    region: Region,
    *,
    ground_z: float | None = None,
    prior_yaw: float | None = None,
    cls: str | None = None,
    config: FitConfig | None = None,
) -> FitResult:
    """Fit a box to the LiDAR points in ``region`` (see the module docstring).

    Args:
        points: ``(N, >=3)`` LiDAR frame (intensity and other columns ignored).
        region: Where the object is: a rough :class:`BoxRegion` or a :class:`DiskRegion`.
        ground_z: Ground height (m) when known; else estimated.
        prior_yaw: Heading to stay close to; default the rough box's yaw, or 0 for a disk.
        cls: The object's class: with a typical size (its ``ObjectClass.mean_size``) and a
            minimum (``config.class_min_sizes``), a rectangle below the minimum is completed away
            from the sensor (step 5). None (or another class): the points alone decide.
        config: Parameters (default :class:`FitConfig()`).

    Raises:
        FitError: Fewer than ``config.min_points`` points remain; the message gives the count.
    """
    cfg = config if config is not None else FitConfig()
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise ValueError(f"fit_box: points must have shape (N, >=3), got {pts.shape}")
    finite = np.all(np.isfinite(pts[:, :3]), axis=1)
    xy, z = pts[:, :2], pts[:, 2]
    selected = _in_region(xy, region) & finite
    where = "the selected region"
    if not selected.any():
        raise FitError(f"no LiDAR points in {where}: move or enlarge it")
    if ground_z is None:
        ground_z = _local_ground(pts, region, cfg.ground_margin)
    ground_z = float(ground_z)
    above = selected & (z > ground_z + cfg.ground_clearance) & (z <= ground_z + cfg.max_height)
    n_above = int(above.sum())
    if n_above < cfg.min_points:
        raise FitError(
            f"only {n_above} LiDAR point(s) above the ground (z > {ground_z + cfg.ground_clearance:.2f}"
            f" m) in {where} ({int(selected.sum())} in total); a fit needs at least "
            f"{cfg.min_points}: move or enlarge the region, or place the box by hand"
        )
    used = above.copy()
    if cfg.cluster_gap is not None:
        idx = np.nonzero(above)[0]
        keep = _largest_cluster(xy[idx], cfg.cluster_gap)
        used[idx[~keep]] = False
        if int(used.sum()) < cfg.min_points:
            raise FitError(
                f"the largest group of points in {where} has only {int(used.sum())} point(s); "
                f"a fit needs at least {cfg.min_points}"
            )
    seen = min_area_rectangle(xy[used])  # not yet widened to min_size: the faces at the points
    rect = _at_least(seen, cfg.min_size)
    completed = False
    minimum = cfg.class_minimum(cls) if cls is not None else None
    if minimum is not None and cls in ALL_CLASSES and seen.length > 0:
        typical = object_class(cls).mean_size[:2]
        full, completed = complete_rectangle(seen, typical, minimum, cfg)
        if completed:
            rect = _at_least(full, cfg.min_size)
    if prior_yaw is None:
        prior_yaw = region.box[6] if isinstance(region, BoxRegion) else 0.0
    yaw = rect.yaw
    if abs(wrap_yaw(yaw + np.pi - prior_yaw)) < abs(wrap_yaw(yaw - prior_yaw)):
        yaw = yaw + np.pi
    top = float(z[used].max())
    bottom = ground_z if cfg.extend_to_ground else float(z[used].min())
    height = max(top - bottom, cfg.min_size)
    box = np.array(
        [
            rect.centre[0],
            rect.centre[1],
            bottom + height / 2.0,
            rect.length,
            rect.width,
            height,
            wrap_yaw(yaw),
        ]
    )
    return FitResult(
        box=box, num_points=int(used.sum()), ground_z=ground_z, used=used, completed=completed
    )
