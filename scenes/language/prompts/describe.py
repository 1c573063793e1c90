"""A sentence for a given set of actors (the annotation tool's suggester).

:func:`describe_predicate` searches the predicate language from simple to complex for one that
refers to exactly the set; :func:`describe` renders it as a Talk2Radar-style noun phrase (no
command frame, sentence case, a period, digits; the vocabulary of the ``train`` phrasings).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from scenes.geometry.actors import MOVING_SPEED, Actor
from scenes.language.prompts.atoms import (
    ABOUT_DEPTH_TOL,
    BASE_EXTREMES,
    Atom,
    DepthAbout,
    DepthBetween,
    DepthBeyond,
    DepthWithin,
    Extreme,
    Heading,
    HeadingIs,
    MotionState,
    OnSide,
    Side,
    SpeedAbout,
    SpeedAbove,
    SpeedBelow,
    SpeedUnit,
)
from scenes.language.prompts.features import (
    DEFAULT_REGION,
    ActorFeatures,
    ReferableRegion,
    actor_features,
)
from scenes.language.prompts.predicate import Predicate, analyse_features
from scenes.language.prompts.render import Prompt, render_with_variants


def _candidate_atoms(subset: Sequence[ActorFeatures]) -> list[Atom]:
    """Atoms true of every actor in ``subset``, simplest / roundest first."""
    cands: list[Atom] = [OnSide(s) for s in Side]
    cands += [MotionState(True), MotionState(False)]
    cands += [HeadingIs(h) for h in Heading]
    dmin = min(f.depth for f in subset)
    dmax = max(f.depth for f in subset)
    if dmax - dmin <= 2 * ABOUT_DEPTH_TOL - 1.0:
        centre = (dmin + dmax) / 2
        cands += [DepthAbout(float(v)) for v in (5 * round(centre / 5), round(centre)) if v >= 3]
    lo5, hi5 = 5 * math.floor((dmin - 0.5) / 5), 5 * math.ceil((dmax + 0.5) / 5)
    lo1, hi1 = math.floor(dmin - 0.5), math.ceil(dmax + 0.5)
    cands += [DepthWithin(float(hi5)), DepthWithin(float(hi1))]
    cands += [DepthBeyond(float(v)) for v in (lo5, lo1) if v >= 1]
    cands += [DepthBetween(float(lo), float(hi)) for lo, hi in ((lo5, hi5), (lo1, hi1)) if lo >= 1]
    smin = min(f.speed for f in subset)
    smax = max(f.speed for f in subset)
    if smin > MOVING_SPEED:
        kmh_mid = 3.6 * (smin + smax) / 2
        cands.append(SpeedAbout(float(5 * round(kmh_mid / 5)), SpeedUnit.KMH))
        if round((smin + smax) / 2) >= 1:
            cands.append(SpeedAbout(float(round((smin + smax) / 2)), SpeedUnit.MPS))
        cands += [
            SpeedAbove(float(v), SpeedUnit.KMH)
            for v in (5 * math.floor((3.6 * smin - 3.0) / 5),)
            if v >= 5
        ]
        cands += [SpeedAbove(float(v), SpeedUnit.MPS) for v in (math.floor(smin - 0.5),) if v >= 1]
        cands.append(SpeedBelow(float(5 * math.ceil((3.6 * smax + 3.0) / 5)), SpeedUnit.KMH))
        cands.append(SpeedBelow(float(math.ceil(smax + 0.5)), SpeedUnit.MPS))
    unique: list[Atom] = []
    for a in cands:
        if a not in unique and all(a.holds(f) for f in subset):
            unique.append(a)
    return unique


def describe_predicate(
    actors_subset: Sequence[Actor],
    all_actors: Sequence[Actor],
    region: ReferableRegion = DEFAULT_REGION,
) -> Predicate | None:
    """The simplest predicate that refers to exactly ``actors_subset`` (see :func:`describe`)."""
    feats = actor_features(all_actors)
    by_id = {f.actor_id: f for f in feats}
    want_ids = sorted({int(a.actor_id) for a in actors_subset})
    if not want_ids or any(i not in by_id for i in want_ids):
        return None
    subset = [by_id[i] for i in want_ids]
    if not all(region.contains(f) for f in subset):
        return None
    want = tuple(want_ids)
    classes = {f.cls for f in subset}
    cls_options: list[str | None] = [next(iter(classes)), None] if len(classes) == 1 else [None]
    extremes: list[Extreme | None] = [None]
    if len(subset) == 1:
        extremes += list(BASE_EXTREMES)
    atoms = _candidate_atoms(subset)
    fallback: Predicate | None = None
    for k in range(4):
        for combo in itertools.combinations(atoms, k):
            if len({a.family for a in combo}) != k:
                continue
            for extreme in extremes if k <= 1 else [None]:
                for cls in cls_options:
                    try:
                        pred = Predicate(cls, combo, extreme)
                    except ValueError:
                        continue
                    res = analyse_features(pred, feats, region)
                    if res.ids != want or res.conflicts:
                        continue
                    if res.crisp:
                        return pred
                    if fallback is None:
                        fallback = pred
    return fallback


def describe(
    actors_subset: Sequence[Actor],
    all_actors: Sequence[Actor],
    rng: np.random.Generator,
    *,
    region: ReferableRegion = DEFAULT_REGION,
    max_words: int = 22,
) -> Prompt | None:
    """A sentence whose predicate selects exactly ``actors_subset`` among ``all_actors``.

    Predicates are tried from simple to complex (class alone; then 1, 2, 3 attributes true of
    every member; a superlative for a single actor), the first crisp one wins, else the first
    exact one that is not crisp. None when the subset is empty, holds an actor that is not
    referable or not in ``all_actors``, or no predicate of the language selects exactly it (for
    example two of three parked cars side by side). The sentence follows
    :func:`~scenes.language.prompts.render.render` with no frame, no restyling and digits.
    """
    pred = describe_predicate(actors_subset, all_actors, region)
    if pred is None:
        return None
    ids = tuple(sorted({int(a.actor_id) for a in actors_subset}))
    text, variants = render_with_variants(
        pred,
        len(ids),
        rng,
        p_frame=0.0,
        p_restyle=0.0,
        p_number_words=0.0,
        max_words=max_words,
    )
    return Prompt(text, ids, pred.tags, pred, variants)
