"""Actor meshes (cars, pedestrians, cyclists and the bicycle parts shared with parked bicycles),
built in the actor's box frame (centre at the origin, heading +x, z up) and scaled so that their
axis-aligned bounds are exactly the sampled ``l, w, h``."""

from __future__ import annotations

import numpy as np

from scenes.synth.world.materials import Mat
from scenes.synth.world.meshes import (
    TaggedMesh,
    box_part,
    cylinder_part,
    ellipsoid_part,
    fit_to_box,
    hexahedron_part,
)

CAR_SIZE = ((3.5, 5.0), (1.6, 2.0), (1.4, 1.8))
PEDESTRIAN_SIZE = ((0.5, 0.9), (0.5, 0.9), (1.5, 1.9))
CYCLIST_SIZE = ((1.6, 1.9), (0.5, 0.8), (1.5, 1.9))
"""``(l, w, h)`` ranges in metres per class."""

RIDER_IN_CYCLIST = (0.48, 1.0, 0.1, 1.0)
"""Where the rider of :func:`cyclist_mesh` is in the cyclist's box: its length and width as shares
of the box's (centred), and its bottom and top as shares of the box's height above the box's bottom
(measured on the rider's clothing and skin over 135 random cyclists: length 0.47..0.48, full width,
bottom 0.07..0.16, top 1.0; the pedals hang lowest). View-of-Delft labels this person separately
as a ``rider`` inside the ``Cyclist`` box (about 0.45 of its length and 0.9 of its height in the
devkit's example frames)."""

DARK_CLOTHING = 0.5
"""Share of pedestrians and riders in dark clothes (:attr:`Mat.CLOTHING_DARK`, about 12 %
reflective at the LiDAR's 905 nm, against 40 %): dark coats and jeans are common in Delft, and
they are what makes far people sparse and dim in the HDL-64's scans (its data sheet gives 50 m for
a 10 % target)."""


def clothing(rng: np.random.Generator) -> Mat:
    """One person's clothing material: dark with probability :data:`DARK_CLOTHING`."""
    return Mat.CLOTHING_DARK if rng.random() < DARK_CLOTHING else Mat.CLOTHING


def car_mesh(size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """A car: bevelled body, glass cabin with a painted roof, four wheels. Bounds = ``size``."""
    l, w, h = size
    zb = -h / 2.0
    paint = Mat.PAINT_DARK if rng.random() < 0.5 else Mat.PAINT_LIGHT
    clearance, r_wheel = 0.17, rng.uniform(0.30, 0.35)
    body_top = zb + h * rng.uniform(0.52, 0.60)
    hl, hw = l / 2.0, w / 2.0
    nose, tail = rng.uniform(0.10, 0.25), rng.uniform(0.05, 0.15)
    body = hexahedron_part(
        tapered_corners(
            x_bottom=(-hl, hl),
            x_top=(-hl + tail, hl - nose),
            y_bottom=hw,
            y_top=hw * 0.97,
            z=(zb + clearance, body_top),
        ),
        paint,
    )
    rear = -hl + l * rng.uniform(0.08, 0.22)
    front = hl - l * rng.uniform(0.30, 0.38)
    cabin = hexahedron_part(
        tapered_corners(
            x_bottom=(rear, front),
            x_top=(rear + 0.15, front - rng.uniform(0.35, 0.6)),
            y_bottom=hw * 0.94,
            y_top=hw * 0.80,
            z=(body_top, zb + h),
        ),
        Mat.CAR_GLASS,
        top_mat=paint,
    )
    parts = [body, cabin]
    axle = hl - rng.uniform(0.65, 0.90)
    for x in (-axle, axle):
        for side in (-1.0, 1.0):
            y_out, y_in = side * (hw - 0.02), side * (hw - 0.24)
            parts.append(
                cylinder_part(
                    [x, y_in, zb + r_wheel], [x, y_out, zb + r_wheel], r_wheel, Mat.RUBBER
                )
            )
    return fit_to_box(TaggedMesh.concatenate(parts), size)


def tapered_corners(
    x_bottom: tuple[float, float],
    x_top: tuple[float, float],
    y_bottom: float,
    y_top: float,
    z: tuple[float, float],
) -> np.ndarray:
    """Hexahedron corners (unit-box order) of a prism symmetric in y, tapering from bottom to top."""
    out = np.zeros((8, 3))
    for i in range(8):
        bx, by, bz = (i >> 2) & 1, (i >> 1) & 1, i & 1
        xs = x_top if bz else x_bottom
        half = y_top if bz else y_bottom
        out[i] = (xs[bx], half if by else -half, z[bz])
    return out


def pedestrian_mesh(size: np.ndarray, walking: bool, rng: np.random.Generator) -> TaggedMesh:
    """A pedestrian in outdoor clothes: two legs (in stride when walking), hips, coat-clad torso,
    two arms, head, and sometimes a shoulder bag or backpack. Bounds = ``size``."""
    h = 1.75
    cloth = clothing(rng)
    stride = rng.uniform(0.22, 0.32) if walking else rng.uniform(0.0, 0.05)
    hip, shoulder = 0.48 * h, 0.82 * h
    parts = []
    for side, phase in ((-1.0, 1.0), (1.0, -1.0)):
        foot = [phase * stride, side * 0.1, 0.05]
        parts.append(cylinder_part([0.0, side * 0.1, hip], foot, 0.085, cloth))
        hand = [-phase * stride * 0.8, side * 0.25, 0.47 * h]
        parts.append(cylinder_part([0.0, side * 0.21, shoulder], hand, 0.055, cloth))
    parts.append(ellipsoid_part([0.0, 0.0, hip + 0.02], [0.13, 0.19, 0.13], cloth))
    parts.append(ellipsoid_part([0.0, 0.0, (hip + shoulder) / 2 + 0.03], [0.15, 0.22, 0.3], cloth))
    if rng.random() < 0.4:
        parts.append(ellipsoid_part([-0.2, 0.0, 0.7 * h], [0.1, 0.16, 0.2], Mat.CLOTHING))
    parts.append(ellipsoid_part([0.02, 0.0, h - 0.11], [0.1, 0.085, 0.11], Mat.SKIN))
    mesh = TaggedMesh.concatenate(parts)
    return fit_to_box(mesh, size)


def bicycle_parts(rng: np.random.Generator) -> list[TaggedMesh]:
    """A Dutch city bicycle (wheels with mudguards, frame, chain guard, handlebar, often a crate or
    panniers) in its own frame: wheels at ``x = +-0.52``, ground at ``z = 0``, heading +x."""
    r = 0.34
    rear, front = [-0.52, 0.0, r], [0.52, 0.0, r]
    bracket, seat, stem = [-0.05, 0.0, 0.30], [-0.22, 0.0, 0.88], [0.38, 0.0, 0.98]
    parts = [cylinder_part([x, -0.03, r], [x, 0.03, r], r, Mat.RUBBER) for x in (rear[0], front[0])]
    for x in (rear[0], front[0]):  # mudguards over the upper half of the wheels
        parts.append(box_part([x - 0.3, -0.05, r + 0.12], [x + 0.3, 0.05, r + 0.4], Mat.BIKE_FRAME))
    for a, b in ((rear, bracket), (bracket, seat), (seat, stem), (stem, front), (rear, seat)):
        parts.append(cylinder_part(a, b, 0.03, Mat.BIKE_FRAME))
    parts.append(box_part([-0.55, -0.06, 0.22], [0.0, 0.06, 0.42], Mat.BIKE_FRAME))  # chain guard
    parts.append(cylinder_part([0.38, -0.3, 1.0], [0.38, 0.3, 1.0], 0.025, Mat.BIKE_FRAME))
    load = rng.random()
    if load < 0.35:  # front crate
        parts.append(box_part([0.45, -0.2, 0.72], [0.85, 0.2, 1.0], Mat.BIKE_FRAME))
    elif load < 0.7:  # rear rack with panniers
        parts.append(box_part([-0.75, -0.24, 0.45], [-0.3, 0.24, 0.8], Mat.CLOTHING))
    return parts


def cyclist_mesh(size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """A cyclist: a city bicycle (:func:`bicycle_parts`) and a rider in a jacket (a backpack
    sometimes). Bounds = ``size``."""
    parts = bicycle_parts(rng)
    cloth = clothing(rng)
    lean = rng.uniform(0.25, 0.4)
    shoulders = [-0.2 + lean, 0.0, 1.42]
    parts.append(cylinder_part([-0.22, 0.0, 0.85], shoulders, 0.22, cloth))
    if rng.random() < 0.3:  # backpack
        parts.append(
            ellipsoid_part([shoulders[0] - 0.3, 0.0, 1.2], [0.12, 0.16, 0.22], Mat.CLOTHING)
        )
    parts.append(ellipsoid_part([shoulders[0] + 0.06, 0.0, 1.61], [0.11, 0.1, 0.12], Mat.SKIN))
    crank = rng.uniform(0, 2 * np.pi)
    for side, phase in ((-1.0, 0.0), (1.0, np.pi)):
        pedal = [
            -0.05 + 0.17 * np.cos(crank + phase),
            side * 0.12,
            0.3 + 0.17 * np.sin(crank + phase),
        ]
        parts.append(cylinder_part([-0.2, side * 0.12, 0.92], pedal, 0.09, cloth))
        parts.append(
            cylinder_part([shoulders[0], side * 0.22, 1.4], [0.36, side * 0.27, 1.0], 0.06, cloth)
        )
    return fit_to_box(TaggedMesh.concatenate(parts), size)


def rider_boxes(cyclists: np.ndarray) -> np.ndarray:
    """The riders' boxes ``(K, 7)`` of cyclist boxes ``(K, 7)`` (LiDAR frame, z at the geometric
    centre): :data:`RIDER_IN_CYCLIST` of each box, same centre in x and y, same yaw."""
    b = np.asarray(cyclists, dtype=np.float64).reshape(-1, 7).copy()
    length, width, bottom, top = RIDER_IN_CYCLIST
    height = b[:, 5].copy()
    b[:, 2] += height * ((bottom + top) / 2.0 - 0.5)
    b[:, 3] *= length
    b[:, 4] *= width
    b[:, 5] = height * (top - bottom)
    return b
