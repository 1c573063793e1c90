"""The generator's own wording of a rewording case: the reference the rewording family is read
against.

A rewording sentence says what one of the generator's predicates says (class, side, motion,
heading, speed, depth, a superlative) in other words. :func:`generator_sentence` builds that
predicate from the hand-written query (:func:`predicate_of`), keeps the case only where the
generator's own resolution (:func:`scenes.language.prompts.analyse`) refers to exactly the suite's
referents without ambiguity, and renders it with the generator's training wording
(:func:`scenes.language.prompts.render`, a generator seeded from the case). The runner grounds both
sentences on the same encoded scene, so the difference between the two rows is the wording alone.
This is the one module of the suite that imports :mod:`scenes.language.prompts`; the suite's resolver does
not.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence

import numpy as np

from scenes.geometry.actors import Actor
from scenes.language.prompts import (
    DepthAbout,
    DepthBetween,
    DepthBeyond,
    DepthWithin,
    Extreme,
    Heading,
    MotionState,
    Predicate,
    Side,
    SpeedAbout,
    SpeedAbove,
    SpeedBelow,
    SpeedUnit,
    analyse,
    render,
)
from scenes.language.prompts import HeadingIs as GenHeading
from scenes.language.prompts import OnSide as GenSide
from scenes.language.query import Cond, Depth, HeadingIs, Moving, Not, OnSide, Query, Speed

_EXTREMES = {
    "nearest": Extreme.NEAREST,
    "farthest": Extreme.FARTHEST,
    "leftmost": Extreme.LEFTMOST,
    "rightmost": Extreme.RIGHTMOST,
    "fastest": Extreme.FASTEST,
}
_SPEEDS = {"speed_above": SpeedAbove, "speed_below": SpeedBelow, "speed_about": SpeedAbout}
_UNITS = {"kmh": SpeedUnit.KMH, "mps": SpeedUnit.MPS}


def _atom(cond: Cond) -> object | None:
    if isinstance(cond, Moving):
        return MotionState(True)
    if isinstance(cond, Not) and isinstance(cond.cond, Moving):
        return MotionState(False)
    if isinstance(cond, OnSide):
        return GenSide(Side(cond.side))
    if isinstance(cond, HeadingIs):
        return GenHeading(Heading(cond.heading))
    if isinstance(cond, Speed):
        return _SPEEDS[cond.op](cond.value, _UNITS[cond.unit])
    if isinstance(cond, Depth):
        if cond.op == "depth_between":
            assert cond.hi is not None
            return DepthBetween(cond.lo, cond.hi)
        return {
            "depth_about": DepthAbout,
            "depth_beyond": DepthBeyond,
            "depth_within": DepthWithin,
        }[cond.op](cond.lo)
    return None


def predicate_of(query: Query) -> Predicate | None:
    """The generator's predicate with the query's meaning, None where it has none (negations
    other than "not moving", relations, ranks past the first, exclusions, two atoms of a family)."""
    if query.out_of_class is not None or query.exclusion is not None:
        return None
    atoms = [_atom(c) for c in query.where]
    if any(a is None for a in atoms):
        return None
    extreme = None
    if query.rank is not None:
        if query.rank.index != 1 or query.rank.key not in _EXTREMES:
            return None
        extreme = _EXTREMES[query.rank.key]
    try:
        return Predicate(cls=query.cls, atoms=tuple(atoms), extreme=extreme)  # type: ignore[arg-type]
    except ValueError:
        return None


def generator_sentence(
    query: Query, actors: Sequence[Actor], referents: Sequence[int], case_key: str
) -> str | None:
    """The generator's sentence for ``query`` in this scene, or None where the generator cannot
    say it or would refer to other actors (module docstring)."""
    pred = predicate_of(query)
    if pred is None:
        return None
    res = analyse(pred, list(actors))
    if res.conflicts or not res.crisp or tuple(res.ids) != tuple(sorted(referents)):
        return None
    rng = np.random.default_rng(zlib.crc32(case_key.encode()))
    return render(pred, len(res.ids), rng)
