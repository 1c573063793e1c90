"""Prompts generated from a frame's actors, each with its exact referent set.

Each attempt draws an anchor among the referable actors and attributes true of it, resolves the
predicate over all actors (:mod:`scenes.language.prompts.predicate`) and renders a sentence from the size
of the resolved set (:mod:`scenes.language.prompts.render`), so a stated count always equals the number of
referents: count is not a filter, it is said from the resolved set.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import replace

import numpy as np

from scenes.geometry.actors import Actor
from scenes.language.prompts.commands import commands_for
from scenes.language.prompts.extended import generate_extended
from scenes.language.prompts.features import (
    DEFAULT_REGION,
    ActorFeatures,
    ReferableRegion,
    actor_features,
)
from scenes.language.prompts.noise import perturb
from scenes.language.prompts.phrasing.slot_choice import too_wide
from scenes.language.prompts.predicate import Predicate, analyse_features, usable_referents
from scenes.language.prompts.render import Prompt, render_with_variants
from scenes.language.prompts.sampling import PromptConfig, draw_anchor, sample_predicate

__all__ = ["PromptConfig", "generate_prompts", "motion_hypotheses", "motion_robust"]

HYPOTHESIS_SPEEDS = (0.8, 2.0, 5.0, 10.0, 20.0)
"""m/s: the speeds an actor of unknown motion is tried at (:func:`motion_hypotheses`), along and
against its heading and across it both ways, beside standing still: they straddle the generator's
moving threshold and its speed words' round numbers."""


def generate_prompts(
    actors: Sequence[Actor],
    rng: np.random.Generator,
    n: int,
    *,
    region: ReferableRegion = DEFAULT_REGION,
    config: PromptConfig | None = None,
    unknown_motion: Collection[int] = (),
) -> list[Prompt]:
    """Up to ``n`` distinct prompts about the scene, each with its exact referent set.

    Each attempt draws an anchor among the referable actors, attributes true of it (class, depth,
    position, motion or heading, speed; 0-3 of them plus the class, sometimes a superlative),
    resolves the predicate over all actors and keeps it when it refers to something, has no
    conflicts, is crisp (unless ``config.require_crisp`` is False) and neither the predicate nor
    the text was emitted before. Fewer than ``n`` prompts come back when the scene does not admit
    ``n`` (none when no actor is referable). Deterministic for a given ``rng`` state.
    ``config`` defaults to :class:`PromptConfig()`. ``config.p_perturb`` > 0 rewrites that share
    of the texts with :func:`scenes.language.prompts.noise.perturb` (referents and tags kept);
    ``config.command_share`` > 0 first phrases that share of the single-referent prompts as driving
    commands (:func:`scenes.language.prompts.commands.commands_for`; referents kept). With ``config.language == "extended"`` the
    prompts come from :func:`scenes.language.prompts.extended.generate_extended` (every family of
    :data:`~scenes.language.prompts.sampling.FAMILIES`, some with an empty referent set).

    ``unknown_motion``: ids of actors whose velocity is not known (labelled boxes whose motion
    the data does not tell, :mod:`scenes.nuscenes.motion`; their ``velocity`` is a placeholder):
    only prompts whose referents hold whatever those actors do are kept
    (:func:`motion_robust`), and none is phrased as a command about such an actor.

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
    unknown = frozenset(int(i) for i in unknown_motion)
    if config.language == "extended":
        out = generate_extended(actors, rng, n, region=region, config=config)
        out = [p for p in out if motion_robust(p, actors, unknown, region)]
    else:
        out = _generate_base(actors, rng, n, region, config, unknown)
    if config.command_share > 0.0 and out:
        commands = np.random.default_rng(int(rng.integers(2**63)))
        by_id = {a.actor_id: a for a in actors if a.actor_id not in unknown}
        out = commands_for(
            out,
            by_id,
            commands,
            config.command_share,
            config.phrasing,
            config.max_words,
            config.people_share,
            config.classes,
        )
    if config.p_perturb <= 0.0 or not out:
        return out
    noise = np.random.default_rng(int(rng.integers(2**63)))
    return [
        replace(p, text=perturb(p.text, noise)) if noise.random() < config.p_perturb else p
        for p in out
    ]


def _generate_base(
    actors: Sequence[Actor],
    rng: np.random.Generator,
    n: int,
    region: ReferableRegion,
    config: PromptConfig,
    unknown: frozenset[int] = frozenset(),
) -> list[Prompt]:
    """The base language's prompts (:func:`generate_prompts`)."""
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
        anchor = draw_anchor(inside, rng, config)
        pred = sample_predicate(anchor, rng, config)
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
        wide = too_wide(variants, config.classes)
        if key in seen_text or len(text.split()) > config.max_words or wide:
            continue
        prompt = Prompt(text, res.ids, pred.tags, pred, variants)
        if not motion_robust(prompt, actors, unknown, region):
            continue
        seen_text.add(key)
        out.append(prompt)
    return out


def motion_hypotheses(actor: Actor) -> list[np.ndarray]:
    """Ground velocities ``(2,)`` an actor of unknown motion might have: standing still, and
    each of :data:`HYPOTHESIS_SPEEDS` along and against its heading and across it both ways."""
    yaw = float(actor.box[6])
    along = np.array([np.cos(yaw), np.sin(yaw)])
    across = np.array([-along[1], along[0]])
    out = [np.zeros(2)]
    for speed in HYPOTHESIS_SPEEDS:
        out += [speed * along, -speed * along, speed * across, -speed * across]
    return out


def motion_robust(
    prompt: Prompt,
    actors: Sequence[Actor],
    unknown: Collection[int],
    region: ReferableRegion = DEFAULT_REGION,
) -> bool:
    """Whether ``prompt``'s referent set stays what it is, and unambiguous, whatever the actors
    ``unknown`` (ids) do: resolved again with each of :func:`motion_hypotheses` given to all of
    them at once (hypothesis ``i`` to each; a predicate filters actors one by one, so this tries
    every hypothesis on every actor). Without unknown actors, always; a prompt of another family
    than ``attribute`` (no predicate to resolve again) only without them."""
    if not unknown:
        return True
    if prompt.predicate is None or prompt.family != "attribute" or prompt.expression is not None:
        return False
    moved = [i for i, a in enumerate(actors) if a.actor_id in unknown]
    if not moved or not prompt.predicate.reads_motion:
        return True  # no velocity can change what it refers to
    feats = actor_features(actors)
    hypotheses = [motion_hypotheses(actors[i]) for i in moved]
    for h in range(len(hypotheses[0])):
        tried = list(feats)  # only the moved actors' features change
        for i, options in zip(moved, hypotheses, strict=True):
            tried[i] = ActorFeatures.of(replace(actors[i], velocity=options[h]))
        if usable_referents(prompt.predicate, tried, region) != prompt.referent_ids:
            return False
    return True
