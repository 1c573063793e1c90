"""Predicates over a frame's actors and their exact resolution to referents.

A :class:`Predicate` is a conjunction: an optional class (``None`` = any class), at most one atom
per family (:mod:`scenes.language.prompts.atoms`) and an optional superlative. :func:`resolve` evaluates it
over *all* referable actors, so "the cars moving away from us" refers to every such car.

Referable region and ambiguity. Only actors inside a
:class:`~scenes.language.prompts.features.ReferableRegion` (default: centre ``x`` in ``[0, 50]`` m and
``|bearing| <= 32`` degrees, the View-of-Delft annotated area and camera field of view) can be
referents. An actor outside it but close to it (within ``guard_m`` metres in x or ``guard_deg``
degrees in bearing) is still visible in the sensors, so a sentence that would also describe it is
ambiguous: :func:`analyse` lists such actors as ``conflicts``, and the generator and ``describe``
never emit a predicate with conflicts. Actors far outside (behind the ego vehicle, well beyond
50 m) are out of the scene the prompt speaks about and are ignored.

Crispness. A predicate is *crisp* when its resolved set does not change when every threshold moves
by one unit of slack (:mod:`scenes.language.prompts.atoms`) and a superlative's winner beats the runner-up
by a clear margin. This keeps borderline actors (a car 17.4 m away for "about 20 m") from making a
true sentence look wrong to a person or a model.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from scenes.geometry.actors import MOVING_SPEED, Actor
from scenes.geometry.classes import ALL_CLASSES
from scenes.language.prompts.atoms import FAMILY_ORDER, SLACK_MOTION, Atom, Extreme
from scenes.language.prompts.features import (
    DEFAULT_REGION,
    ActorFeatures,
    ReferableRegion,
    actor_features,
)

MOTION_FAMILIES = ("motion", "heading", "speed")
"""The atom families that read an actor's velocity (:attr:`Predicate.reads_motion`)."""


@dataclass(frozen=True)
class Predicate:
    """A conjunction: optional class, at most one atom per family, optional superlative.

    Atoms are stored in a canonical order, so equal predicates compare and hash equal.
    """

    cls: str | None = None
    atoms: tuple[Atom, ...] = ()
    extreme: Extreme | None = None

    def __post_init__(self) -> None:
        if self.cls is not None and self.cls not in ALL_CLASSES:
            raise ValueError(f"Predicate: class {self.cls!r} is not one of {ALL_CLASSES}")
        atoms = tuple(self.atoms)
        for a in atoms:
            if not isinstance(a, Atom):
                raise ValueError(f"Predicate: {a!r} is not an Atom")
        families = [a.family for a in atoms]
        if len(set(families)) != len(families):
            raise ValueError(f"Predicate: at most one atom per family, got {families}")
        atoms = tuple(sorted(atoms, key=lambda a: FAMILY_ORDER.index(a.family)))
        object.__setattr__(self, "atoms", atoms)

    @property
    def tags(self) -> frozenset[str]:
        """The prompt type tags of any sentence rendered from this predicate."""
        tags = {a.tag for a in self.atoms}
        if self.cls is not None:
            tags.add("class")
        if self.extreme is not None:
            tags.add(self.extreme.tag)
        return frozenset(tags)

    def flipped(self) -> Predicate:
        """The predicate that says the same of the world flipped y -> -y (left <-> right)."""
        extreme = self.extreme.flipped() if self.extreme is not None else None
        return Predicate(self.cls, tuple(a.flipped() for a in self.atoms), extreme)

    @property
    def reads_motion(self) -> bool:
        """Whether the referents can depend on the actors' velocities: a motion, heading or speed
        atom, or a ranking by speed (every other test reads only class and position)."""
        by_speed = self.extreme is not None and self.extreme.tag == "velocity"
        return by_speed or any(a.family in MOTION_FAMILIES for a in self.atoms)

    def matches(self, actor: Actor | ActorFeatures, slack: float = 0.0) -> bool:
        """Class and atoms (not the superlative) hold for the actor."""
        f = actor if isinstance(actor, ActorFeatures) else ActorFeatures.of(actor)
        if self.cls is not None and f.cls != self.cls:
            return False
        return all(a.holds(f, slack) for a in self.atoms)


@dataclass(frozen=True)
class Resolution:
    """What a predicate refers to in a scene.

    Attributes:
        ids: Referent actor ids (referable actors satisfying it), ascending.
        conflicts: Ids of visible but non-referable actors (the region's guard band) it also
            describes; a non-empty tuple makes the sentence ambiguous.
        crisp: The referents do not change under small threshold slack (module docstring).
    """

    ids: tuple[int, ...]
    conflicts: tuple[int, ...]
    crisp: bool

    @property
    def usable(self) -> bool:
        """Refers to something, unambiguously."""
        return bool(self.ids) and not self.conflicts


def _select(pred: Predicate, inside: Sequence[ActorFeatures], slack: float) -> tuple[int, ...]:
    cands = [f for f in inside if pred.matches(f, slack)]
    if pred.extreme is None:
        return tuple(sorted(f.actor_id for f in cands))
    cands = [f for f in cands if pred.extreme.ranks(f)]
    if not cands:
        return ()
    best = max(cands, key=lambda f: (pred.extreme.key(f), -f.actor_id))
    if pred.extreme is Extreme.FASTEST and best.speed <= MOVING_SPEED:
        return ()
    return (best.actor_id,)


def all_clearly_moving(pred: Predicate, inside: Sequence[ActorFeatures]) -> bool:
    """Every actor ``pred`` matches (its superlative aside) moves faster than
    :data:`~scenes.geometry.actors.MOVING_SPEED` by the motion slack: what makes a ranking by slowness
    crisp (a standing or borderline actor might be said to be the slowest)."""
    return all(f.speed > MOVING_SPEED + SLACK_MOTION for f in inside if pred.matches(f, 1.0))


def _conflicts(pred: Predicate, f: ActorFeatures, region: ReferableRegion) -> bool:
    """Whether ``f`` makes ``pred`` ambiguous: in the guard band around the referable region and
    matched with a unit of slack (:attr:`Resolution.conflicts`)."""
    return region.in_guard(f) and pred.matches(f, 1.0)


def usable_referents(
    pred: Predicate, feats: Sequence[ActorFeatures], region: ReferableRegion
) -> tuple[int, ...] | None:
    """The ids :func:`analyse_features` gives when its resolution is usable, else None, without
    its crispness tests (what :func:`scenes.language.prompts.generate.motion_robust` asks of
    every motion hypothesis)."""
    ids = _select(pred, [f for f in feats if region.contains(f)], 0.0)
    if not ids or any(_conflicts(pred, f, region) for f in feats):
        return None
    return ids


def analyse_features(
    pred: Predicate, feats: Sequence[ActorFeatures], region: ReferableRegion
) -> Resolution:
    """:func:`analyse` on precomputed :class:`ActorFeatures` (the generator's inner loop)."""
    inside = [f for f in feats if region.contains(f)]
    ids = _select(pred, inside, 0.0)
    crisp = _select(pred, inside, -1.0) == ids == _select(pred, inside, 1.0)
    if crisp and pred.extreme is not None:
        scores = sorted((pred.extreme.key(f) for f in inside if pred.matches(f)), reverse=True)
        crisp = len(scores) < 2 or scores[0] - scores[1] >= pred.extreme.gap
        if pred.extreme is Extreme.FASTEST and scores:
            crisp = crisp and scores[0] > MOVING_SPEED + SLACK_MOTION
        if pred.extreme is Extreme.SLOWEST:
            crisp = crisp and all_clearly_moving(pred, inside)
    conflicts = tuple(sorted(f.actor_id for f in feats if _conflicts(pred, f, region)))
    return Resolution(ids=ids, conflicts=conflicts, crisp=crisp)


def analyse(
    predicate: Predicate, actors: Sequence[Actor], region: ReferableRegion = DEFAULT_REGION
) -> Resolution:
    """Referents, ambiguity conflicts and crispness of a predicate over a scene's actors."""
    return analyse_features(predicate, actor_features(actors), region)


def resolve(
    predicate: Predicate, actors: Sequence[Actor], region: ReferableRegion = DEFAULT_REGION
) -> tuple[int, ...]:
    """Ids (ascending) of the referable actors the predicate refers to, evaluated over all actors."""
    return analyse(predicate, actors, region).ids
