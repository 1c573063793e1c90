"""Prompts generated from a frame's actors, each with its exact referent set.

Each attempt draws an anchor among the referable actors and attributes true of it, resolves the
predicate over all actors (:mod:`scenes.prompts.predicate`) and renders a sentence from the size
of the resolved set (:mod:`scenes.prompts.render`), so a stated count always equals the number of
referents: count is not a filter, it is said from the resolved set.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from scenes.actors import MOVING_SPEED, Actor
from scenes.prompts.atoms import (
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
from scenes.prompts.features import DEFAULT_REGION, ActorFeatures, ReferableRegion, actor_features
from scenes.prompts.phrasing import PHRASINGS
from scenes.prompts.predicate import Predicate, analyse_features
from scenes.prompts.render import Prompt, render_with_variants


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
        require_crisp: Only emit crisp predicates (:mod:`scenes.prompts.predicate`).
        plural_bias: Probability of redrawing a predicate that refers to a single actor, to come
            closer to Talk2Radar's mix (about 2.4 referred objects per prompt).
        tries_per_prompt: Sampling attempts per requested prompt before giving up.
        phrasing: ``train`` (only train phrasing variants), ``heldout`` (every sentence uses at
            least one held-out variant where it can) or ``all`` (:mod:`scenes.prompts.phrasing`).
        p_frame: Probability of a command / question frame ("show me ...", "where is ...").
        p_restyle: Probability, each, of another casing, end punctuation or phrase joiner than
            sentence case, a period and spaces.
        p_number_words: Probability of numbers in words before a spelled-out unit.
        geometry_only: Only attributes a box alone decides (class, depth, side, superlatives of
            distance): for prompts generated from labelled boxes whose motion is unknown.
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

    def __post_init__(self) -> None:
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
        )
        for name in probabilities:
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"PromptConfig: {name}={p} is not a probability")
        if self.phrasing not in PHRASINGS:
            raise ValueError(f"PromptConfig: phrasing={self.phrasing!r} is not one of {PHRASINGS}")


def _depth_atom(f: ActorFeatures, rng: np.random.Generator) -> Atom | None:
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


def _speed_atom(f: ActorFeatures, rng: np.random.Generator) -> Atom | None:
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


def _side_of(f: ActorFeatures) -> Side | None:
    for side in Side:
        if OnSide(side).holds(f):
            return side
    return None


def _sample_predicate(
    f: ActorFeatures, rng: np.random.Generator, cfg: PromptConfig
) -> Predicate | None:
    moving = f.speed > MOVING_SPEED and not cfg.geometry_only
    families = ["depth"] if cfg.geometry_only else ["depth", "motion"]
    side = _side_of(f)
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
            atom = _depth_atom(f, rng)
        elif fam == "position":
            atom = OnSide(side) if side is not None else None
        elif fam == "speed":
            atom = _speed_atom(f, rng)
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
        kinds = [e for e in Extreme if e is not Extreme.FASTEST or moving]
        extreme = kinds[int(rng.integers(len(kinds)))]
    if cls is None and not atoms and extreme is None:
        return None
    return Predicate(cls, tuple(atoms), extreme)


def generate_prompts(
    actors: Sequence[Actor],
    rng: np.random.Generator,
    n: int,
    *,
    region: ReferableRegion = DEFAULT_REGION,
    config: PromptConfig | None = None,
) -> list[Prompt]:
    """Up to ``n`` distinct prompts about the scene, each with its exact referent set.

    Each attempt draws an anchor among the referable actors, attributes true of it (class, depth,
    position, motion or heading, speed; 0-3 of them plus the class, sometimes a superlative),
    resolves the predicate over all actors and keeps it when it refers to something, has no
    conflicts, is crisp (unless ``config.require_crisp`` is False) and neither the predicate nor
    the text was emitted before. Fewer than ``n`` prompts come back when the scene does not admit
    ``n`` (none when no actor is referable). Deterministic for a given ``rng`` state.
    ``config`` defaults to :class:`PromptConfig()`.

    Sentences are drawn from a generator seeded once from ``rng``, so the predicates drawn do
    not depend on the wording: the ``train`` and ``heldout`` phrasings of one ``rng`` state say
    the same predicates in other words (up to the rare prompt whose sentence in one wording
    repeats an earlier one or runs past ``config.max_words`` and is skipped).

    Raises:
        ValueError: ``n < 0`` or duplicate actor ids.
    """
    if n < 0:
        raise ValueError(f"generate_prompts: n must be >= 0, got {n}")
    config = config if config is not None else PromptConfig()
    feats = actor_features(actors)
    inside = [f for f in feats if region.contains(f)]
    out: list[Prompt] = []
    if not inside or n == 0:
        return out
    words_rng = np.random.default_rng(int(rng.integers(2**63)))
    seen_pred: set[Predicate] = set()
    seen_text: set[str] = set()
    for _ in range(n * config.tries_per_prompt):
        if len(out) >= n:
            break
        anchor = inside[int(rng.integers(len(inside)))]
        pred = _sample_predicate(anchor, rng, config)
        if pred is None or pred in seen_pred:
            continue
        res = analyse_features(pred, feats, region)
        if not res.usable or (config.require_crisp and not res.crisp):
            continue
        if len(res.ids) == 1 and rng.random() < config.plural_bias:
            continue
        seen_pred.add(pred)
        text, variants = render_with_variants(
            pred,
            len(res.ids),
            words_rng,
            phrasing=config.phrasing,
            p_count_word=config.p_count_word,
            p_adjective=config.p_adjective,
            p_frame=config.p_frame,
            p_restyle=config.p_restyle,
            p_number_words=config.p_number_words,
            max_words=config.max_words,
        )
        key = text.lower().rstrip(".!?")
        if key in seen_text or len(text.split()) > config.max_words:
            continue
        seen_text.add(key)
        out.append(Prompt(text, res.ids, pred.tags, pred, variants))
    return out
