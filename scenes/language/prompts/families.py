"""The compositional prompt families and their exact semantics over a frame's actors.

Every expression resolves over the referable actors of a
:class:`~scenes.language.prompts.features.ReferableRegion` to a :class:`~scenes.language.prompts.predicate.Resolution`
(ids, possibly empty; guard-band ``conflicts``; ``crisp``), with the discipline of
:mod:`scenes.language.prompts.predicate`: the generator emits only expressions without conflicts whose
referents do not change within one unit of threshold slack. Definitions (LiDAR frame, centres
``(x, y)``, depth = nearest-edge forward distance, far edge = ``2 x - depth``):

* :class:`Not` -- negation of any atom: true of an actor where the atom is false. Inside a
  :class:`Predicate` it is the complement within the class and the other atoms; with slack ``s``
  it is ``not atom.holds(f, -s)``, so crispness rejects an actor near the atom's threshold.
* :class:`Travel` -- a heading atom: moving with the velocity within 30 degrees of our direction
  of travel (+x, "heading the same way as us") or of the opposite one (-x, "coming the other
  way"), told apart by the sign of the ground radial velocity.
* :class:`Behind` -- a position atom: behind the ego vehicle (centre at negative x), outside the
  forward annotated area, so never true of a referable actor ("the car behind us").
* unsatisfiable -- a plain :class:`Predicate` that resolves to no actor, crisp: no actor satisfies
  it even with one unit of slack (loosened), and no guard-band actor does. The generator also
  writes contradictions (two atoms no actor meets at once: "the parked car approaching us"),
  places behind us, and distances and speeds beyond any actor (:mod:`scenes.language.prompts.extended`).
* :class:`Exclusion` -- ``base`` minus ``removed``: ``removed`` is ``base`` plus one atom
  ("every car but the ones on the right") or ``base`` with a superlative ("all the pedestrians
  except the nearest one"); both crisp, the removed set non-empty and a proper subset.
* :class:`Ordinal` -- the ``rank``-th (2..4) actor of ``base`` ranked by a superlative's key
  ("the second closest cyclist", "the third car from the left", "the farthest but one"); crisp
  when ``base`` is and each of the first ``rank`` consecutive scores beats the next by the
  superlative's gap (the next after the ``rank``-th included, when there is one).
* :class:`Related` -- ``target`` actors (not the reference itself) in a relation to a reference
  object: ``reference`` resolves crisply to exactly one actor (:data:`BETWEEN`: to exactly two,
  "the two cars"). Relations, with slack ``s``:

  - ``closest_to``: the one target with the smallest centre distance to the reference; crisp when
    the runner-up is at least :data:`CLOSEST_GAP` m farther.
  - ``behind``: farther from us, in line: ``0 < t.depth - ref.far_edge <= 15`` m (``+- 0.5 s``)
    and ``|t.y - ref.y| <= 2`` m (``+ 0.25 s``).
  - ``next_to``: centre distance ``<= 4`` m (``+ 0.5 s``).
  - ``between``: the centre projects onto the segment between the two references' centres at a
    fraction in ``[0.1, 0.9]`` (``+- 0.05 s``), within ``2`` m (``+ 0.25 s``) of the line; the
    references at least 4 m apart.
* :class:`Count` -- "how many ...": the referents are the counted set of ``base`` (possibly
  empty), crisp when ``base`` is.
* out-of-class (:mod:`scenes.language.prompts.nouns`) -- a thing none of the classes covers: no referent.
"""

from __future__ import annotations

import enum
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

from scenes.geometry.actors import MOVING_SPEED
from scenes.language.prompts.atoms import SLACK_ANGLE, SLACK_DEPTH, SLACK_MOTION, Atom, Extreme
from scenes.language.prompts.features import ActorFeatures, ReferableRegion
from scenes.language.prompts.predicate import (
    Predicate,
    Resolution,
    all_clearly_moving,
    analyse_features,
)

Cache = dict[Predicate, Resolution]
"""Resolutions of predicates over one scene (the generator's memo; keyed by predicate only, so
one cache serves one ``(feats, region)``)."""


def analyse_cached(
    cache: Cache | None, feats: Sequence[ActorFeatures], region: ReferableRegion, pred: Predicate
) -> Resolution:
    """:func:`~scenes.language.prompts.predicate.analyse_features`, memoised in ``cache`` (None: not)."""
    if cache is None:
        return analyse_features(pred, feats, region)
    res = cache.get(pred)
    if res is None:
        res = cache[pred] = analyse_features(pred, feats, region)
    return res


@dataclass(frozen=True)
class Not(Atom):
    """The negation of an atom (same family and tag as the atom; module docstring)."""

    atom: Atom

    def __post_init__(self) -> None:
        if isinstance(self.atom, Not) or not isinstance(self.atom, Atom):
            raise ValueError(f"Not: needs a plain atom, got {self.atom!r}")

    @property
    def family(self) -> str:  # type: ignore[override]
        return self.atom.family

    @property
    def tag(self) -> str:  # type: ignore[override]
        return self.atom.tag

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        return not self.atom.holds(f, -slack)

    def flipped(self) -> Not:
        return Not(self.atom.flipped())


class Direction(enum.Enum):
    """Direction of travel relative to ours (:class:`Travel`)."""

    SAME = "same"
    OPPOSITE = "opposite"


TRAVEL_MAX_ANGLE_DEG = 30.0
"""Largest angle (degrees) between a :class:`Travel` actor's velocity and the x axis."""


@dataclass(frozen=True)
class Travel(Atom):
    """Moving along our direction of travel (``SAME``: velocity within 30 degrees of +x, "heading
    the same way as us") or against it (``OPPOSITE``: within 30 degrees of -x, "coming the other
    way"). Inside the camera's field of view the sign of the ground radial velocity tells +x from
    -x (a velocity within 30 degrees of the axis and a line of sight within 32 degrees of it are
    at most 62 degrees apart). Slack moves the speed threshold and the angle."""

    direction: Direction
    family: ClassVar[str] = "heading"
    tag: ClassVar[str] = "motion"

    @property
    def slot(self) -> str:
        """Its phrase's slot (:mod:`scenes.language.prompts.phrasing.family_slots`)."""
        return f"travel.{self.direction.value}"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        if f.speed <= MOVING_SPEED - SLACK_MOTION * slack:
            return False
        if f.crossing_angle_deg < 90.0 - TRAVEL_MAX_ANGLE_DEG - SLACK_ANGLE * slack:
            return False
        return f.radial_velocity > 0 if self.direction is Direction.SAME else f.radial_velocity < 0


@dataclass(frozen=True)
class Behind(Atom):
    """Behind the ego vehicle (box centre at negative x): outside every referable region (the
    annotated area is the camera's forward field of view), so a predicate with it is
    unsatisfiable and its answer is empty ("the car behind us"). Slack moves the line by
    :data:`~scenes.language.prompts.atoms.SLACK_DEPTH` metres."""

    family: ClassVar[str] = "position"
    tag: ClassVar[str] = "position"
    slot: ClassVar[str] = "position.behind"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        return f.x < SLACK_DEPTH * slack


def negated(pred: Predicate) -> Atom | None:
    """The :class:`Not` atom of a predicate (None when it has none)."""
    return next((a for a in pred.atoms if isinstance(a, Not)), None)


@dataclass(frozen=True)
class Exclusion:
    """``base`` minus ``removed`` (module docstring)."""

    base: Predicate
    removed: Predicate

    def __post_init__(self) -> None:
        if self.base.extreme is not None:
            raise ValueError("Exclusion: the base set has no superlative")
        same = self.removed.cls == self.base.cls
        plus_atom = set(self.base.atoms) < set(self.removed.atoms)
        if not same or not (plus_atom or self.removed.extreme is not None):
            raise ValueError("Exclusion: removed must be base plus one atom or a superlative")

    def analyse(
        self, feats: Sequence[ActorFeatures], region: ReferableRegion, cache: Cache | None = None
    ) -> Resolution:
        b = analyse_cached(cache, feats, region, self.base)
        r = analyse_cached(cache, feats, region, self.removed)
        ids = tuple(sorted(set(b.ids) - set(r.ids)))
        crisp = b.crisp and r.crisp and bool(r.ids) and set(r.ids) < set(b.ids)
        return Resolution(ids, b.conflicts, crisp)

    def flipped(self) -> Exclusion:
        return Exclusion(self.base.flipped(), self.removed.flipped())


@dataclass(frozen=True)
class Ordinal:
    """The ``rank``-th actor of ``base`` by ``extreme`` (module docstring)."""

    base: Predicate
    extreme: Extreme
    rank: int

    def __post_init__(self) -> None:
        if self.base.extreme is not None or not 2 <= self.rank <= 4:
            raise ValueError(f"Ordinal: rank {self.rank} not in 2..4 or base has a superlative")

    def analyse(
        self, feats: Sequence[ActorFeatures], region: ReferableRegion, cache: Cache | None = None
    ) -> Resolution:
        b = analyse_cached(cache, feats, region, self.base)
        by_id = {f.actor_id: f for f in feats}
        ranked = sorted((by_id[i] for i in b.ids), key=lambda f: (-self.extreme.key(f), f.actor_id))
        ranked = [f for f in ranked if self.extreme.ranks(f)]
        if len(ranked) < self.rank:
            return Resolution((), b.conflicts, b.crisp)
        chosen = ranked[self.rank - 1]
        scores = [self.extreme.key(f) for f in ranked[: self.rank + 1]]
        gaps = all(a - b_ >= self.extreme.gap for a, b_ in itertools.pairwise(scores))
        crisp = b.crisp and gaps
        if self.extreme is Extreme.FASTEST:
            crisp = crisp and chosen.speed > MOVING_SPEED + SLACK_MOTION
        if self.extreme is Extreme.SLOWEST:
            inside = [f for f in feats if region.contains(f)]
            crisp = crisp and all_clearly_moving(self.base, inside)
        return Resolution((chosen.actor_id,), b.conflicts, crisp)

    def flipped(self) -> Ordinal:
        return Ordinal(self.base.flipped(), self.extreme.flipped(), self.rank)


class Relation(enum.Enum):
    """Relations to a reference object (module docstring)."""

    CLOSEST_TO = "closest_to"
    BEHIND = "behind"
    NEXT_TO = "next_to"
    BETWEEN = "between"


CLOSEST_GAP = 1.0
"""Smallest runner-up margin (m) of a crisp ``closest_to``."""
BEHIND_MAX_GAP = 15.0
IN_LINE_Y = 2.0
NEXT_TO_DISTANCE = 4.0
BETWEEN_FRACTION = (0.1, 0.9)
BETWEEN_LINE_DISTANCE = 2.0
BETWEEN_MIN_SEPARATION = 4.0


def relation_holds(
    relation: Relation, t: ActorFeatures, refs: Sequence[ActorFeatures], slack: float = 0.0
) -> bool:
    """Whether target ``t`` stands in ``relation`` (not ``CLOSEST_TO``) to the reference(s)."""
    if relation is Relation.BEHIND:
        r = refs[0]
        gap = t.depth - (2 * r.x - r.depth)
        return (
            -0.5 * slack < gap <= BEHIND_MAX_GAP + 0.5 * slack
            and abs(t.y - r.y) <= IN_LINE_Y + 0.25 * slack
        )
    if relation is Relation.NEXT_TO:
        r = refs[0]
        return math.hypot(t.x - r.x, t.y - r.y) <= NEXT_TO_DISTANCE + 0.5 * slack
    if relation is Relation.BETWEEN:
        a, b = refs
        dx, dy = b.x - a.x, b.y - a.y
        length2 = dx * dx + dy * dy
        u = ((t.x - a.x) * dx + (t.y - a.y) * dy) / length2
        dist = abs((t.x - a.x) * dy - (t.y - a.y) * dx) / math.sqrt(length2)
        lo, hi = BETWEEN_FRACTION
        return (
            lo - 0.05 * slack <= u <= hi + 0.05 * slack
            and dist <= BETWEEN_LINE_DISTANCE + 0.25 * slack
        )
    raise ValueError(f"relation_holds: {relation} is a superlative relation")


@dataclass(frozen=True)
class Related:
    """``target`` actors in ``relation`` to the actor(s) ``reference`` picks (module docstring)."""

    target: Predicate
    relation: Relation
    reference: Predicate

    def __post_init__(self) -> None:
        if self.target.extreme is not None:
            raise ValueError("Related: the target has no superlative")

    @property
    def n_references(self) -> int:
        """How many actors the reference must resolve to."""
        return 2 if self.relation is Relation.BETWEEN else 1

    def analyse(
        self, feats: Sequence[ActorFeatures], region: ReferableRegion, cache: Cache | None = None
    ) -> Resolution:
        ref = analyse_cached(cache, feats, region, self.reference)
        t = analyse_cached(cache, feats, region, self.target)
        conflicts = tuple(sorted(set(ref.conflicts) | set(t.conflicts)))
        if len(ref.ids) != self.n_references:
            return Resolution((), conflicts, False)
        by_id = {f.actor_id: f for f in feats}
        refs = [by_id[i] for i in ref.ids]
        cands = [by_id[i] for i in t.ids if i not in ref.ids]
        crisp = ref.crisp and t.crisp
        if self.relation is Relation.CLOSEST_TO:
            r = refs[0]
            dists = sorted((math.hypot(f.x - r.x, f.y - r.y), f.actor_id) for f in cands)
            if not dists:
                return Resolution((), conflicts, crisp)
            if len(dists) > 1:
                crisp = crisp and dists[1][0] - dists[0][0] >= CLOSEST_GAP
            return Resolution((dists[0][1],), conflicts, crisp)
        if self.relation is Relation.BETWEEN:
            a, b = refs
            if math.hypot(a.x - b.x, a.y - b.y) < BETWEEN_MIN_SEPARATION:
                return Resolution((), conflicts, False)
        ids = tuple(sorted(f.actor_id for f in cands if relation_holds(self.relation, f, refs)))
        for s in (-1.0, 1.0):
            moved = tuple(
                sorted(f.actor_id for f in cands if relation_holds(self.relation, f, refs, s))
            )
            crisp = crisp and moved == ids
        return Resolution(ids, conflicts, crisp)

    def flipped(self) -> Related:
        return Related(self.target.flipped(), self.relation, self.reference.flipped())


@dataclass(frozen=True)
class Count:
    """ "How many ...": the counted set of ``base`` (module docstring)."""

    base: Predicate

    def __post_init__(self) -> None:
        if self.base.extreme is not None:
            raise ValueError("Count: the counted set has no superlative")

    def analyse(
        self, feats: Sequence[ActorFeatures], region: ReferableRegion, cache: Cache | None = None
    ) -> Resolution:
        return analyse_cached(cache, feats, region, self.base)

    def flipped(self) -> Count:
        return Count(self.base.flipped())


Expression = Exclusion | Ordinal | Related | Count
"""A compositional expression (module docstring)."""


def unsatisfiable(pred: Predicate, feats: Sequence[ActorFeatures], region: ReferableRegion) -> bool:
    """``pred`` refers to nothing, crisply: no referable or guard-band actor satisfies it, even
    loosened by one unit of slack (a superlative of an empty set is empty)."""
    loose = Predicate(pred.cls, pred.atoms)
    return not any(
        (region.contains(f) or region.in_guard(f)) and loose.matches(f, 1.0) for f in feats
    )


__all__ = [
    "Behind",
    "Count",
    "Direction",
    "Exclusion",
    "Expression",
    "Not",
    "Ordinal",
    "Related",
    "Relation",
    "Travel",
    "analyse_cached",
    "negated",
    "relation_holds",
    "unsatisfiable",
]
