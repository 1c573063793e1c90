"""A scene the extended generator draws prompts from, and the draws every family shares.

:class:`DrawScene` holds one scene's actor features, the referable region, the random streams and
a resolution cache; :func:`sampled` draws a predicate true of an actor; :func:`fake_actor` imagines
an actor that is not there (out-of-class places, unsatisfiable and counting prompts).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from scenes.geometry.actors import Actor
from scenes.geometry.classes import class_set
from scenes.language.prompts.families import Count, Exclusion, Ordinal, Related, analyse_cached
from scenes.language.prompts.features import ActorFeatures, ReferableRegion
from scenes.language.prompts.predicate import Predicate, Resolution
from scenes.language.prompts.render import Style
from scenes.language.prompts.sampling import PromptConfig, draw_anchor, sample_predicate

ABSURD_SPEED = {
    "Car": (22.0, 90.0),
    "Pedestrian": (4.0, 30.0),
    "Cyclist": (10.0, 40.0),
    "Truck": (20.0, 60.0),
    "Bus": (18.0, 60.0),
    "Trailer": (20.0, 60.0),
    "ConstructionVehicle": (5.0, 40.0),
    "Motorcycle": (22.0, 90.0),
    "Bicycle": (10.0, 40.0),
    "TrafficCone": (1.0, 30.0),
    "Barrier": (1.0, 30.0),
}
"""Ground speeds (m/s) no actor of a class reaches, for the unsatisfiable family: from about 1.5
times the fastest of its class in the world (:mod:`scenes.synth.world.placement`: cars 15, cyclists 7,
pedestrians 2 m/s; :mod:`scenes.synth.world.road_users`: trucks and buses 12, motorcycles 14,
construction vehicles 1.5, cones and barriers never move) up, so that "a pedestrian doing
25 km/h" is said as well as "doing 100"."""
_FAKE_SIZE = {"Car": (4.5, 1.8, 1.6), "Pedestrian": (0.6, 0.6, 1.7), "Cyclist": (1.8, 0.6, 1.7)}


@dataclass
class DrawScene:
    """One scene being drawn from: its actors' features, the region, the random streams
    (``rng`` for content, ``words`` for wording), the config and a resolution cache."""

    feats: list[ActorFeatures]
    inside: list[ActorFeatures]
    region: ReferableRegion
    rng: np.random.Generator
    words: np.random.Generator
    cfg: PromptConfig
    style: Style
    cache: dict = field(default_factory=dict)

    def anchor(self) -> ActorFeatures:
        """A referable actor (:func:`~scenes.language.prompts.sampling.draw_anchor`)."""
        return draw_anchor(self.inside, self.rng, self.cfg)

    def analyse(self, pred: Predicate) -> Resolution:
        return analyse_cached(self.cache, self.feats, self.region, pred)

    def resolve(self, expr: Exclusion | Ordinal | Related | Count) -> Resolution:
        return expr.analyse(self.feats, self.region, self.cache)

    def ok(self, res: Resolution) -> bool:
        """Unambiguous, and crisp where the config asks for it."""
        return not res.conflicts and (res.crisp or not self.cfg.require_crisp)


def sampled(sc: DrawScene, f: ActorFeatures, max_atoms: int, extreme: bool) -> Predicate | None:
    """A predicate true of ``f``, with its class, at most ``max_atoms`` atoms."""
    pred = sample_predicate(f, sc.rng, sc.cfg)
    if pred is None:
        return None
    atoms = pred.atoms[:max_atoms]
    return Predicate(f.cls, atoms, pred.extreme if extreme else None)


def fake_actor(sc: DrawScene, far: bool = False, fast: bool = False) -> ActorFeatures:
    """Features of an imagined actor in the region: a random class, place and motion. ``far``:
    60-400 m ahead, beyond any annotated actor; ``fast``: faster than its class moves
    (:data:`ABSURD_SPEED`)."""
    rng = sc.rng
    x = float(rng.uniform(60.0, 400.0) if far else rng.uniform(4.0, 48.0))
    y = float(np.tan(np.radians(rng.uniform(-28.0, 28.0))) * min(x, 48.0))
    names = class_set(sc.cfg.classes).names
    cls = names[int(rng.integers(len(names)))]
    if fast:
        speed = float(rng.uniform(*ABSURD_SPEED[cls]))
    else:
        speed = 0.0 if rng.random() < 0.35 else float(rng.uniform(1.0, 14.0))
    heading = float(rng.uniform(-math.pi, math.pi))
    size = _FAKE_SIZE.get(cls) or class_set(sc.cfg.classes).get(cls).mean_size
    v = (speed * math.cos(heading), speed * math.sin(heading))
    return ActorFeatures.of(Actor(-1, cls, [x, y, size[2] / 2, *size, heading], v))
