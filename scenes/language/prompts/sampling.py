"""The generator's settings and its attribute sampling: predicates true of an anchor actor.

:class:`PromptConfig` holds every sampling knob of :func:`scenes.language.prompts.generate_prompts`
(the semantics are fixed module constants elsewhere); :func:`sample_predicate` draws a
:class:`~scenes.language.prompts.predicate.Predicate` of 0-3 attributes true of one actor, plus its class
and sometimes a superlative.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from scenes.geometry.actors import MOVING_SPEED
from scenes.geometry.classes import PRESETS
from scenes.language.prompts.atoms import (
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
from scenes.language.prompts.features import ActorFeatures
from scenes.language.prompts.phrasing.split import PHRASINGS
from scenes.language.prompts.predicate import Predicate

LANGUAGES = ("base", "extended")
"""Values of ``PromptConfig.language``."""

FAMILIES = (
    "attribute",
    "out_of_class",
    "unsatisfiable",
    "negation",
    "exclusion",
    "ordinal",
    "relation",
    "count",
)
"""Prompt families (:attr:`scenes.language.prompts.render.Prompt.family`); ``attribute`` is today's
predicate language, the others come with ``language="extended"`` (:mod:`scenes.language.prompts.families`)."""

EXTENDED_RATES = (0.07, 0.11, 0.07, 0.07, 0.14, 0.14, 0.04)
"""Default shares of the non-attribute families in :data:`FAMILIES` order (out-of-class,
unsatisfiable, negation, exclusion, ordinal, relation, count); the attribute family gets the rest."""


@dataclass(frozen=True)
class PromptConfig:
    """Sampling settings of :func:`generate_prompts` (the semantics are fixed module constants).

    Attributes:
        attribute_weights: Probabilities of 0, 1, 2, 3 non-class attributes.
        p_class: Probability of naming the class (always named when no attribute is drawn).
        p_extreme: Probability of a superlative.
        p_count_word: Probability of stating the count of a plural referent set.
        p_adjective: Probability of saying one attribute before the noun ("the parked cars").
        max_words: Longest sentence in words (Talk2Radar's text encoder keeps 30 tokens).
        require_crisp: Only emit crisp predicates (:mod:`scenes.language.prompts.predicate`).
        plural_bias: Probability of redrawing a predicate that refers to a single actor, to come
            closer to Talk2Radar's mix (about 2.4 referred objects per prompt).
        tries_per_prompt: Sampling attempts per requested prompt before giving up.
        phrasing: ``train`` (only train phrasing variants), ``heldout`` (every sentence uses at
            least one held-out variant where it can) or ``all`` (:mod:`scenes.language.prompts.phrasing`).
        p_frame: Probability of a command / question frame ("show me ...", "where is ...").
        p_restyle: Probability, each, of another casing, end punctuation or phrase joiner than
            sentence case, a period and spaces.
        p_number_words: Probability of numbers in words before a spelled-out unit.
        geometry_only: Only attributes a box alone decides (class, depth, side, superlatives of
            distance): for prompts generated from labelled boxes whose motion is unknown.
        language: ``base`` (the attribute family only, the wording of
            :mod:`scenes.language.prompts.phrasing`; byte-identical to the generator before the option) or
            ``extended`` (every family of :data:`FAMILIES` and the wider wording of
            :mod:`scenes.language.prompts.phrasing.extra` and :mod:`scenes.language.prompts.phrasing.family_slots`).
        family_rates: ``extended`` only: the share of prompts of each non-attribute family, in
            :data:`FAMILIES` order after ``attribute`` (:data:`EXTENDED_RATES`); the rest are
            attribute prompts. A family the scene does not admit is redrawn, so realised shares
            drift towards the families every scene admits (out-of-class, attribute).
        p_nonsense: ``extended`` only: share of out-of-class prompts that are nonsense text.
        p_perturb: Probability of rewriting each prompt's text with
            :func:`scenes.language.prompts.noise.perturb` (meaning kept: referents and tags stay); 0 draws
            nothing, so the prompts are those without the option.
        command_share: Share of the single-referent prompts (not counting questions) phrased as
            a driving command about their referent ("follow the car on the left",
            :mod:`scenes.language.prompts.commands`; the wording stream is ``phrasing``'s);
            referents kept. 0 draws nothing, so the prompts are those without the option.
        people_share: Share of those commands said the way people say them
            (:mod:`scenes.language.prompts.people`: the manoeuvre first, colours and clothes,
            people's words for the class, context first); 0 draws nothing.
        classes: The class set the scene's actors are of and the prompts name
            (:data:`scenes.geometry.classes.PRESETS`): ``vod`` draws as the generator always did;
            another set draws each anchor's class uniformly among the classes present (so that
            rare road users are talked about), imagines absent actors of its own classes and
            leaves its classes' nouns out of the out-of-class things.
    """

    attribute_weights: tuple[float, float, float, float] = (0.1, 0.4, 0.35, 0.15)
    p_class: float = 0.9
    p_extreme: float = 0.1
    p_count_word: float = 0.4
    p_adjective: float = 0.35
    max_words: int = 22
    require_crisp: bool = True
    plural_bias: float = 0.5
    tries_per_prompt: int = 40
    phrasing: str = "train"
    geometry_only: bool = False
    p_frame: float = 0.35
    p_restyle: float = 0.35
    p_number_words: float = 0.3
    language: Literal["base", "extended"] = "base"
    family_rates: tuple[float, float, float, float, float, float, float] = EXTENDED_RATES
    p_nonsense: float = 0.1
    p_perturb: float = 0.0
    command_share: float = 0.0
    people_share: float = 0.0
    classes: str = "vod"

    def __post_init__(self) -> None:
        if self.classes not in PRESETS:
            raise ValueError(
                f"PromptConfig: classes={self.classes!r} is not one of {tuple(PRESETS)}"
            )
        w = self.attribute_weights
        if len(w) != 4 or min(w) < 0 or not math.isclose(sum(w), 1.0, abs_tol=1e-6):
            raise ValueError(f"PromptConfig: attribute_weights must be 4 probabilities, got {w}")
        probabilities = (
            "p_class",
            "p_extreme",
            "p_count_word",
            "p_adjective",
            "plural_bias",
            "p_frame",
            "p_restyle",
            "p_number_words",
            "p_nonsense",
            "p_perturb",
            "command_share",
            "people_share",
        )
        for name in probabilities:
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"PromptConfig: {name}={p} is not a probability")
        if self.language not in LANGUAGES:
            raise ValueError(f"PromptConfig: language={self.language!r} is not one of {LANGUAGES}")
        r = self.family_rates
        if len(r) != len(FAMILIES) - 1 or min(r) < 0 or sum(r) > 1.0 + 1e-9:
            raise ValueError(
                f"PromptConfig: family_rates must be {len(FAMILIES) - 1} shares summing to <= 1, got {r}"
            )
        if self.phrasing not in PHRASINGS:
            raise ValueError(f"PromptConfig: phrasing={self.phrasing!r} is not one of {PHRASINGS}")


def draw_anchor(
    inside: Sequence[ActorFeatures], rng: np.random.Generator, cfg: PromptConfig
) -> ActorFeatures:
    """An anchor among the referable actors ``inside`` (non-empty): uniformly with the ``vod``
    class set (one draw, as always); otherwise a class uniformly among those present, then one of
    its actors uniformly (two draws)."""
    if cfg.classes == "vod":
        return inside[int(rng.integers(len(inside)))]
    present = sorted({f.cls for f in inside})
    cls = present[int(rng.integers(len(present)))]
    of_cls = [f for f in inside if f.cls == cls]
    return of_cls[int(rng.integers(len(of_cls)))]


def depth_atom(f: ActorFeatures, rng: np.random.Generator) -> Atom | None:
    """A depth atom true of the actor, on round numbers (None: none drawn)."""
    d = f.depth
    kind = int(rng.integers(4))
    if kind == 0:
        value = round(d) if rng.random() < 0.5 else 5 * round(d / 5)
        return DepthAbout(float(max(value, 3)))
    if kind == 1:
        lo = 5 * math.floor((d - 1.0) / 5)
        hi = lo + 5 if lo + 5 >= d + 1.0 else lo + 10
        return DepthBetween(float(lo), float(hi)) if lo > 0 else DepthWithin(float(hi))
    if kind == 2:
        return DepthWithin(float(5 * math.ceil((d + 1.0) / 5)))
    lo = 5 * math.floor((d - 1.0) / 5)
    return DepthBeyond(float(lo)) if lo >= 5 else None


def speed_atom(f: ActorFeatures, rng: np.random.Generator) -> Atom | None:
    """A speed atom true of the moving actor, in km/h or m/s (None: none drawn)."""
    kmh = f.speed * 3.6
    use_kmh = rng.random() < 0.5 and kmh >= 10.0
    kind = int(rng.integers(3))
    if kind == 0:
        if use_kmh:
            return SpeedAbout(float(5 * round(kmh / 5)), SpeedUnit.KMH)
        value = round(f.speed) if f.speed >= 1.5 else round(f.speed * 2) / 2
        return SpeedAbout(float(value), SpeedUnit.MPS) if value > 0 else None
    if kind == 1:
        if use_kmh:
            v = 5 * math.floor((kmh - 3.0) / 5)
            return SpeedAbove(float(v), SpeedUnit.KMH) if v >= 5 else None
        v = math.floor(f.speed - 0.6)
        return SpeedAbove(float(v), SpeedUnit.MPS) if v >= 1 else None
    if use_kmh:
        return SpeedBelow(float(5 * math.ceil((kmh + 3.0) / 5)), SpeedUnit.KMH)
    return SpeedBelow(float(math.ceil(f.speed + 0.6)), SpeedUnit.MPS)


def side_of(f: ActorFeatures) -> Side | None:
    """The actor's lateral position class (None: beside the bumper, on no side)."""
    for side in Side:
        if OnSide(side).holds(f):
            return side
    return None


def sample_predicate(
    f: ActorFeatures, rng: np.random.Generator, cfg: PromptConfig
) -> Predicate | None:
    """A predicate true of the anchor ``f``: 0-3 attributes (``cfg.attribute_weights``), the
    class (``cfg.p_class``), sometimes a superlative; None when it would say nothing."""
    moving = f.speed > MOVING_SPEED and not cfg.geometry_only
    families = ["depth"] if cfg.geometry_only else ["depth", "motion"]
    side = side_of(f)
    if side is not None:
        families.append("position")
    if moving and f.speed > 1.0:
        families.append("speed")
    k = min(int(rng.choice(4, p=cfg.attribute_weights)), len(families))
    chosen = [families[int(i)] for i in rng.permutation(len(families))[:k]]
    atoms: list[Atom] = []
    for fam in chosen:
        atom: Atom | None
        if fam == "depth":
            atom = depth_atom(f, rng)
        elif fam == "position":
            atom = OnSide(side) if side is not None else None
        elif fam == "speed":
            atom = speed_atom(f, rng)
        elif moving:
            headings = [h for h in Heading if HeadingIs(h).holds(f, -1.0)]
            if headings and (rng.random() < 0.75 or "speed" in chosen):
                atom = HeadingIs(headings[int(rng.integers(len(headings)))])
            else:
                atom = None if "speed" in chosen else MotionState(True)
        else:
            atom = MotionState(False)
        if atom is not None:
            atoms.append(atom)
    cls = f.cls if (rng.random() < cfg.p_class or not atoms) else None
    extreme = None
    if rng.random() < cfg.p_extreme:
        pool = Extreme if cfg.language == "extended" else BASE_EXTREMES
        kinds = [e for e in pool if not e.by_speed or moving]
        extreme = kinds[int(rng.integers(len(kinds)))]
    if cls is None and not atoms and extreme is None:
        return None
    return Predicate(cls, tuple(atoms), extreme)
