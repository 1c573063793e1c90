"""Meshes of the road users beyond cars, pedestrians and cyclists (the ``nuscenes`` class set's
trucks, buses, trailers, construction vehicles, motorcycles, traffic cones and barriers), built
like :mod:`scenes.synth.world.actor_meshes`: in the actor's box frame (centre at the origin,
heading +x, z up) and scaled so that their axis-aligned bounds are exactly the sampled
``l, w, h``. Shapes are coarse solids of the right proportions (a bus is a long box with a window
band and six wheels, a cone a narrow frustum on a square foot, a barrier a tapered concrete or
plastic wall whose long side is its box width ``w``, as nuScenes boxes barriers), which is what the
LiDAR and the radar visibility grid see."""

from __future__ import annotations

import numpy as np

from scenes.synth.world.actor_meshes import clothing, tapered_corners
from scenes.synth.world.materials import Mat
from scenes.synth.world.meshes import (
    TaggedMesh,
    box_part,
    cylinder_part,
    ellipsoid_part,
    fit_to_box,
    frustum_part,
    hexahedron_part,
)

__all__ = [
    "barrier_mesh",
    "bus_mesh",
    "cone_mesh",
    "construction_vehicle_mesh",
    "motorcycle_mesh",
    "trailer_mesh",
    "truck_mesh",
]


def _paint(rng: np.random.Generator) -> Mat:
    return Mat.PAINT_DARK if rng.random() < 0.5 else Mat.PAINT_LIGHT


def _wheels(
    xs: tuple[float, ...], half_w: float, radius: float, z_bottom: float
) -> list[TaggedMesh]:
    """Pairs of wheels at abscissae ``xs`` (box frame of an unscaled model)."""
    parts = []
    for x in xs:
        for side in (-1.0, 1.0):
            y_out, y_in = side * (half_w - 0.02), side * (half_w - 0.32)
            parts.append(
                cylinder_part(
                    [x, y_in, z_bottom + radius], [x, y_out, z_bottom + radius], radius, Mat.RUBBER
                )
            )
    return parts


def truck_mesh(size: np.ndarray, tractor: bool, rng: np.random.Generator) -> TaggedMesh:
    """A truck: a tall cab at the front and, unless ``tractor`` (a semi-trailer's tractor unit,
    a flat chassis with a fifth wheel behind the cab), a cargo box behind it. Bounds = ``size``."""
    l, w, h = 7.0, 2.5, 3.2
    hl, hw, zb = l / 2, w / 2, -h / 2
    paint = _paint(rng)
    cab_len = rng.uniform(1.9, 2.4) if not tractor else rng.uniform(2.4, 2.9)
    cab_top = zb + h * (rng.uniform(0.85, 1.0) if not tractor else 1.0)
    parts = [
        box_part([hl - cab_len, -hw, zb + 0.45], [hl, hw, cab_top - 0.9], paint),
        hexahedron_part(
            tapered_corners(
                (hl - cab_len, hl),
                (hl - cab_len, hl - 0.25),
                hw,
                hw * 0.95,
                (cab_top - 0.9, cab_top),
            ),
            Mat.CAR_GLASS,
            top_mat=paint,
        ),
        box_part([-hl, -hw * 0.6, zb + 0.5], [hl - cab_len, hw * 0.6, zb + 1.0], Mat.METAL),
    ]
    if tractor:
        parts.append(
            cylinder_part([-hl + 1.2, 0.0, zb + 1.0], [-hl + 1.2, 0.0, zb + 1.15], 0.6, Mat.METAL)
        )
    else:
        parts.append(box_part([-hl, -hw, zb + 1.0], [hl - cab_len - 0.1, hw, zb + h], _paint(rng)))
    axles = (
        (hl - 1.2, -hl + 1.3) if tractor or rng.random() < 0.6 else (hl - 1.2, -hl + 1.0, -hl + 2.4)
    )
    parts += _wheels(axles, hw, 0.5, zb)
    return fit_to_box(TaggedMesh.concatenate(parts), size)


def bus_mesh(size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """A city bus: a long body, a window band, a roof unit, two or three axles. Bounds = ``size``."""
    l, w, h = 12.0, 2.55, 3.2
    hl, hw, zb = l / 2, w / 2, -h / 2
    paint = _paint(rng)
    belt, roof = zb + 1.2, zb + h - 0.25
    parts = [
        box_part([-hl, -hw, zb + 0.3], [hl, hw, belt], paint),
        box_part(
            [-hl + 0.05, -hw + 0.02, belt], [hl - 0.05, hw - 0.02, roof - 0.15], Mat.CAR_GLASS
        ),
        box_part([-hl, -hw, roof - 0.15], [hl, hw, roof], paint),
        box_part([-hl * 0.5, -hw * 0.7, roof], [hl * 0.1, hw * 0.7, zb + h], Mat.METAL),
    ]
    axles = (hl - 2.6, -hl + 3.2) if rng.random() < 0.7 else (hl - 2.6, -hl + 3.4, -hl + 2.0)
    parts += _wheels(axles, hw, 0.5, zb)
    return fit_to_box(TaggedMesh.concatenate(parts), size)


def trailer_mesh(size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """A semi-trailer: a box body on a chassis, axles at the rear, landing legs at the front
    (standing on them when parked, on a tractor's fifth wheel when towed). Bounds = ``size``."""
    l, w, h = 13.0, 2.55, 4.0
    hl, hw, zb = l / 2, w / 2, -h / 2
    body = Mat.PAINT_LIGHT if rng.random() < 0.7 else Mat.METAL
    parts = [
        box_part([-hl, -hw, zb + 1.2], [hl, hw, zb + h], body),
        box_part([-hl, -hw * 0.5, zb + 0.9], [hl - 0.5, hw * 0.5, zb + 1.2], Mat.METAL),
    ]
    for side in (-1.0, 1.0):
        parts.append(
            cylinder_part(
                [hl - 2.5, side * 0.9, zb], [hl - 2.5, side * 0.9, zb + 1.2], 0.06, Mat.METAL
            )
        )
    parts += _wheels((-hl + 1.0, -hl + 2.3, -hl + 3.6), hw, 0.5, zb)
    return fit_to_box(TaggedMesh.concatenate(parts), size)


def construction_vehicle_mesh(size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """An excavator (tracks, a turntable with its cab, a boom and a bucket) or a wheel loader (a
    wheeled body, a cab and a front bucket). Bounds = ``size``."""
    l, w, h = 6.5, 2.8, 3.2
    hl, hw, zb = l / 2, w / 2, -h / 2
    parts: list[TaggedMesh] = []
    if rng.random() < 0.6:  # excavator
        for side in (-1.0, 1.0):
            y_in, y_out = sorted((side * (hw - 0.7), side * hw))
            parts.append(box_part([-hl, y_in, zb], [hl * 0.45, y_out, zb + 0.8], Mat.METAL))
        parts.append(
            box_part([-hl, -hw * 0.9, zb + 0.8], [hl * 0.3, hw * 0.9, zb + 1.9], Mat.WORKS_YELLOW)
        )
        parts.append(
            box_part(
                [-hl * 0.1, hw * 0.1, zb + 1.9], [hl * 0.3, hw * 0.9, zb + h - 0.3], Mat.CAR_GLASS
            )
        )
        boom_root, elbow = [hl * 0.3, -0.3, zb + 1.6], [hl * 0.8, -0.3, zb + h]
        parts.append(cylinder_part(boom_root, elbow, 0.18, Mat.WORKS_YELLOW))
        parts.append(cylinder_part(elbow, [hl - 0.3, -0.3, zb + 0.9], 0.14, Mat.WORKS_YELLOW))
        parts.append(box_part([hl - 0.6, -0.7, zb + 0.3], [hl, 0.1, zb + 1.0], Mat.METAL))
    else:  # wheel loader
        parts.append(
            box_part([-hl, -hw * 0.8, zb + 0.6], [hl * 0.45, hw * 0.8, zb + 1.8], Mat.WORKS_YELLOW)
        )
        parts.append(
            box_part([-hl * 0.4, -hw * 0.6, zb + 1.8], [hl * 0.15, hw * 0.6, zb + h], Mat.CAR_GLASS)
        )
        parts.append(box_part([hl - 0.9, -hw, zb + 0.2], [hl, hw, zb + 1.3], Mat.METAL))
        parts += _wheels((-hl + 1.0, hl * 0.3), hw * 0.85, 0.75, zb)
    return fit_to_box(TaggedMesh.concatenate(parts), size)


def motorcycle_mesh(size: np.ndarray, ridden: bool, rng: np.random.Generator) -> TaggedMesh:
    """A motorcycle or scooter (two wheels, engine and tank, seat, handlebar), with its rider when
    ``ridden`` (a person in a jacket and a helmet). Bounds = ``size``."""
    paint = _paint(rng)
    parts = [
        cylinder_part([x, -0.07, 0.32], [x, 0.07, 0.32], 0.32, Mat.RUBBER) for x in (-0.7, 0.72)
    ]
    parts.append(box_part([-0.55, -0.18, 0.35], [0.45, 0.18, 0.8], paint))
    parts.append(box_part([-0.75, -0.16, 0.8], [0.05, 0.16, 0.9], Mat.RUBBER))
    parts.append(cylinder_part([0.72, 0.0, 0.32], [0.5, 0.0, 1.05], 0.04, Mat.METAL))
    parts.append(cylinder_part([0.5, -0.38, 1.05], [0.5, 0.38, 1.05], 0.025, Mat.METAL))
    if ridden:
        cloth = clothing(rng)
        parts.append(cylinder_part([-0.35, 0.0, 0.95], [-0.05, 0.0, 1.5], 0.21, cloth))
        parts.append(ellipsoid_part([0.0, 0.0, 1.68], [0.14, 0.13, 0.14], Mat.PAINT_DARK))
        for side in (-1.0, 1.0):
            parts.append(
                cylinder_part([-0.1, side * 0.2, 1.42], [0.45, side * 0.33, 1.05], 0.06, cloth)
            )
            parts.append(
                cylinder_part([-0.3, side * 0.15, 0.95], [0.05, side * 0.22, 0.45], 0.08, cloth)
            )
    return fit_to_box(TaggedMesh.concatenate(parts), size)


def cone_mesh(size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """A traffic cone: a square rubber foot and an orange frustum with a retro-reflective collar.
    Bounds = ``size`` (the foot sets ``l`` and ``w``)."""
    h = 1.0
    tall = rng.uniform(0.0, 1.0)
    parts = [
        box_part([-0.2, -0.2, 0.0], [0.2, 0.2, 0.04], Mat.RUBBER),
        frustum_part([0.0, 0.0, 0.04], 0.45 * h, 0.16, 0.1, Mat.CONE_ORANGE),
        frustum_part([0.0, 0.0, 0.04 + 0.45 * h], 0.15 * h, 0.1, 0.08, Mat.SIGN),
        frustum_part(
            [0.0, 0.0, 0.04 + 0.6 * h], (0.3 + 0.06 * tall) * h, 0.08, 0.02, Mat.CONE_ORANGE
        ),
    ]
    return fit_to_box(TaggedMesh.concatenate(parts), size)


def barrier_mesh(size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """A road barrier, long along the box's y (its ``w``) and thin along x (its ``l``): a concrete
    jersey barrier (a wall tapering upwards) or a plastic one with a reflective band on feet.
    Bounds = ``size``."""
    if rng.random() < 0.5:
        corners = tapered_corners((-0.3, 0.3), (-0.1, 0.1), 1.25, 1.25, (0.0, 0.9))
        return fit_to_box(TaggedMesh.concatenate([hexahedron_part(corners, Mat.CONCRETE)]), size)
    parts = [
        box_part([-0.05, -1.25, 0.35], [0.05, 1.25, 0.95], Mat.CONE_ORANGE),
        box_part([-0.06, -1.25, 0.6], [0.06, 1.25, 0.75], Mat.SIGN),
    ]
    for y in (-1.0, 1.0):
        parts.append(box_part([-0.3, y - 0.15, 0.0], [0.3, y + 0.15, 0.12], Mat.RUBBER))
        parts.append(box_part([-0.04, y - 0.04, 0.12], [0.04, y + 0.04, 0.35], Mat.METAL))
    return fit_to_box(TaggedMesh.concatenate(parts), size)
