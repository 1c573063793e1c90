"""A world's roadside as drawn, and streets of other densities (:class:`StreetDensity`).

:func:`draw_roadside` draws the frontage, the verges' furniture and the street clutter of both
sides exactly as :func:`scenes.synth.world.generate_world` always has (same draws, same order), and
keeps them apart by kind. :meth:`Roadside.with_density` then thins or thickens them, drawing from
the world's generator *after* the actors (so the actors do not change): a factor below 1 keeps each
item (a building block; a tree, light, sign or bollard with all its parts; a parked bicycle, rack
or moped) with that probability; a factor above 1 draws further layers of the same kind, whose
trees, lights, signs and bollards are dropped where they would overlap an actor, the ego or an
item already there, and whose clutter is placed clear of them (the frontage stands beyond the
building lines, where no actor goes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenes.geometry.actors import Actor
from scenes.synth.world.clutter import Clutter, street_clutter
from scenes.synth.world.config import StreetDensity
from scenes.synth.world.footprint import Obstacle, overlaps_any
from scenes.synth.world.meshes import TaggedMesh
from scenes.synth.world.placement import EGO_FOOTPRINT
from scenes.synth.world.road import Road
from scenes.synth.world.roadside import frontage, furniture

CLEARANCE = 0.3
"""Metres an added tree, light, sign or bollard keeps from an actor (BEV)."""


@dataclass(frozen=True)
class Furniture:
    """One verge item: its footprint and its mesh parts (a tree's trunk and crown, a light's pole,
    arm and lamp...)."""

    obstacle: Obstacle
    parts: tuple[TaggedMesh, ...]


@dataclass(frozen=True)
class Roadside:
    """The roadside of one world, per side (right, then left).

    Attributes:
        frontage: Per side, the building, wall and hedge blocks.
        furniture: Per side, the verge items as drawn (parts, footprints), the parts in draw order.
        clutter: Per side, the clutter's mesh parts and items (``parts[i]`` is ``items[i]``'s).
    """

    frontage: tuple[tuple[TaggedMesh, ...], ...]
    furniture: tuple[tuple[tuple[TaggedMesh, ...], tuple[Obstacle, ...]], ...]
    clutter: tuple[tuple[tuple[TaggedMesh, ...], tuple[Clutter, ...]], ...]

    def parts(self) -> list[TaggedMesh]:
        """Every mesh part in the generator's order: per side frontage then furniture, then the
        clutter of each side."""
        out: list[TaggedMesh] = []
        for front, (furn, _) in zip(self.frontage, self.furniture, strict=True):
            out += [*front, *furn]
        for parts, _ in self.clutter:
            out += parts
        return out

    def items(self) -> list[Clutter]:
        """The clutter items, right side first."""
        return [item for _, items in self.clutter for item in items]

    def with_density(
        self,
        density: StreetDensity,
        actors: tuple[Actor, ...] | list[Actor],
        road: Road,
        ground_z: float,
        rng: np.random.Generator,
    ) -> Roadside:
        """This roadside thinned or thickened by ``density`` (module docstring); draws from
        ``rng`` only (the world's generator once the actors are placed)."""
        taken = [EGO_FOOTPRINT] + [
            np.array([*a.box[:2], a.box[3], a.box[4], a.box[6]]) for a in actors
        ]
        margins = [0.5] + [CLEARANCE] * len(actors)
        sides = (road.right, road.left)
        frontage_out, furniture_out, clutter_out = [], [], []
        obstacles: list[Obstacle] = []
        for k, side in enumerate(sides):
            blocks = _thin(list(self.frontage[k]), density.buildings, rng)
            items = _thin(_group(*self.furniture[k]), density.trees, rng)
            for layer in _layers(density.buildings):
                blocks += _thin(frontage(road, side, ground_z, rng), layer, rng)
            for layer in _layers(density.trees):
                extra = _thin(_group(*furniture(road, side, ground_z, rng)), layer, rng)
                items += [f for f in extra if _clear(f.obstacle, items, taken, margins)]
            frontage_out.append(tuple(blocks))
            furniture_out.append(
                (tuple(p for f in items for p in f.parts), tuple(f.obstacle for f in items))
            )
            obstacles += [f.obstacle for f in items]
        for k, side in enumerate(sides):
            parts, items = self.clutter[k]
            keep = _thin(list(range(len(items))), density.clutter, rng)
            new_parts, new_items = [parts[i] for i in keep], [items[i] for i in keep]
            for item in new_items:
                b = item.box
                obstacles.append(
                    Obstacle(float(b[0]), float(b[1]), float(b[3]), float(b[4]), float(b[6]))
                )
            avoid = obstacles + [Obstacle(*map(float, t)) for t in taken]
            for layer in _layers(density.clutter):
                more_parts, more_items = street_clutter(road, side, ground_z, avoid, rng)
                for i in _thin(list(range(len(more_items))), layer, rng):
                    new_parts.append(more_parts[i])
                    new_items.append(more_items[i])
            clutter_out.append((tuple(new_parts), tuple(new_items)))
        return Roadside(tuple(frontage_out), tuple(furniture_out), tuple(clutter_out))


def draw_roadside(
    road: Road, ground_z: float, rng: np.random.Generator
) -> tuple[Roadside, list[Obstacle]]:
    """Both sides' frontage, furniture and clutter, drawn as the generator always has; with the
    footprints actors must keep clear of (the furniture's and the clutter's)."""
    obstacles: list[Obstacle] = []
    fronts, furn = [], []
    for side in (road.right, road.left):
        fronts.append(tuple(frontage(road, side, ground_z, rng)))
        parts, obs = furniture(road, side, ground_z, rng)
        furn.append((tuple(parts), tuple(obs)))
        obstacles += obs
    clutter = []
    for side in (road.right, road.left):
        parts, items = street_clutter(road, side, ground_z, obstacles, rng)
        clutter.append((tuple(parts), tuple(items)))
    return Roadside(tuple(fronts), tuple(furn), tuple(clutter)), obstacles


def _layers(factor: float) -> list[float]:
    """The shares of the further layers of a factor above 1 (``2.5`` -> ``[1.0, 0.5]``)."""
    extra = max(0.0, factor - 1.0)
    return [min(1.0, extra - k) for k in range(math.ceil(extra))]


def _thin(items: list, share: float, rng: np.random.Generator) -> list:
    """Each of ``items`` kept with probability ``share`` (all of them, and no draw, at >= 1)."""
    if share >= 1.0:
        return items
    draws = rng.random(len(items))
    return [item for item, d in zip(items, draws, strict=True) if d < share]


def _group(parts: list[TaggedMesh] | tuple, obstacles: list[Obstacle] | tuple) -> list[Furniture]:
    """The verge's parts as items: each part goes with the footprint nearest any of its vertices
    (a light's lamp, over the road, with its pole)."""
    if not obstacles:
        return []
    centres = np.array([[o.x, o.y] for o in obstacles])
    owner = [
        int(np.argmin(np.min(np.linalg.norm(p.vertices[:, None, :2] - centres[None], axis=2), 0)))
        for p in parts
    ]
    return [
        Furniture(o, tuple(p for p, k in zip(parts, owner, strict=True) if k == i))
        for i, o in enumerate(obstacles)
    ]


def _clear(
    obstacle: Obstacle, items: list[Furniture], taken: list[np.ndarray], margins: list[float]
) -> bool:
    """Whether an added verge item stands clear of the actors, the ego and the items there."""
    bev = np.array([obstacle.x, obstacle.y, obstacle.l, obstacle.w, obstacle.yaw])
    others = taken + [
        np.array([f.obstacle.x, f.obstacle.y, f.obstacle.l, f.obstacle.w, 0.0]) for f in items
    ]
    return not overlaps_any(bev, 0.1, others, margins + [0.1] * len(items))
