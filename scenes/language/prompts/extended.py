"""The extended language's generator: every family of :data:`~scenes.language.prompts.sampling.FAMILIES`.

:func:`generate_extended` (``PromptConfig(language="extended")``) draws each prompt's family by
``config.family_rates`` (attribute prompts get the rest), samples an expression of that family
from the scene (:mod:`scenes.language.prompts.families`), resolves it exactly and keeps it only when it
has no guard-band conflicts and is crisp; a family the scene does not admit on this draw is
redrawn. Referent sets may be empty (out-of-class, unsatisfiable, a count of zero). The
unsatisfiable family has four forms (:data:`UNSATISFIABLE_FORMS`): an imagined actor's attributes
that fit nobody here, a distance or speed beyond any actor, a place behind us, and a contradiction
(standing still yet approaching, or doing 20 km/h); each is kept only when it resolves crisply to
nothing. Sentences use
the extended wording (:mod:`scenes.language.prompts.phrasing.extra`, :mod:`scenes.language.prompts.phrasing.family_slots`, :mod:`scenes.language.prompts.compose_render`).

Tags: attribute, negation, unsatisfiable and count prompts carry their predicate's tags (the
wording is written so that :func:`~scenes.language.prompts.tags.infer_tags` reads them back); exclusion,
ordinal, relation and out-of-class prompts carry :func:`~scenes.language.prompts.tags.infer_tags` of
their text.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from scenes.geometry.actors import MOVING_SPEED, Actor
from scenes.geometry.classes import PRESETS
from scenes.language.prompts.atoms import (
    Atom,
    Extreme,
    Heading,
    HeadingIs,
    MotionState,
    OnSide,
    SpeedAbove,
    SpeedUnit,
)
from scenes.language.prompts.compose_render import (
    negation_slot,
    render_count,
    render_exclusion,
    render_negation,
    render_ordinal,
    render_plain,
    render_relation,
)
from scenes.language.prompts.families import (
    Count,
    Direction,
    Exclusion,
    Not,
    Ordinal,
    Related,
    Relation,
    Travel,
    relation_holds,
    unsatisfiable,
)
from scenes.language.prompts.features import ActorFeatures, ReferableRegion, actor_features
from scenes.language.prompts.nouns import nonsense, nouns_for
from scenes.language.prompts.phrasing.slot_choice import CLASS_KEYS, too_wide
from scenes.language.prompts.phrasing.split import PHRASINGS
from scenes.language.prompts.predicate import Predicate, Resolution
from scenes.language.prompts.render import Prompt, Style, render_with_variants
from scenes.language.prompts.sampling import (
    FAMILIES,
    PromptConfig,
    depth_atom,
    sample_predicate,
    side_of,
)
from scenes.language.prompts.scene_draw import DrawScene, fake_actor, sampled
from scenes.language.prompts.tags import infer_tags
from scenes.language.prompts.unsatisfiable import UNSATISFIABLE_FORMS

_NOUNS = {(p, c): nouns_for(p, c) for p in PHRASINGS for c in PRESETS}

P_TRAVEL = 0.3
"""Share of attribute prompts with a heading or motion atom whose anchor travels along our axis
that say it as a direction of travel ("heading the same way as us")."""

FAMILY_TRIES = 12
"""Draws of one family before another family is drawn (keeps the realised shares near the rates)."""

_EXTREMES = tuple(Extreme)
P_CLASS_FREE_ORDINAL = 0.2
"""Share of ordinals over every class ("the third closest object"), by depth: the ranks the
referent stage states over all classes (:mod:`model.referent.context`)."""


def _prompt(text: str, variants: tuple[str, ...], ids: Sequence[int], tags, pred, family, expr):
    return Prompt(text, tuple(sorted(ids)), frozenset(tags), pred, variants, family, expr)


def _render(sc: DrawScene) -> dict:
    c = sc.cfg
    return {"style": sc.style, "phrasing": c.phrasing, "max_words": c.max_words}


# ---- families ---------------------------------------------------------------------------------


def _with_travel(pred: Predicate, f: ActorFeatures, sc: DrawScene) -> Predicate:
    """``pred`` with its heading or motion atom said as a direction of travel
    (:class:`~scenes.language.prompts.families.Travel`), sometimes, where one is clearly true of ``f``."""
    directions = [d for d in Direction if Travel(d).holds(f, -1.0)]
    motion = [a for a in pred.atoms if a.family in ("heading", "motion")]
    if not directions or not motion or sc.rng.random() >= P_TRAVEL:
        return pred
    rest = tuple(a for a in pred.atoms if a.family not in ("heading", "motion"))
    return Predicate(pred.cls, (*rest, Travel(directions[0])), pred.extreme)


def _attribute(sc: DrawScene) -> Prompt | None:
    f = sc.anchor()
    pred = sample_predicate(f, sc.rng, sc.cfg)
    if pred is None:
        return None
    pred = _with_travel(pred, f, sc)
    res = sc.analyse(pred)
    if not res.usable or not sc.ok(res):
        return None
    if len(res.ids) == 1 and sc.rng.random() < sc.cfg.plural_bias:
        return None
    c, st = sc.cfg, sc.style
    text, variants = render_with_variants(
        pred,
        len(res.ids),
        sc.words,
        phrasing=c.phrasing,
        p_count_word=st.p_count_word,
        p_adjective=st.p_adjective,
        p_frame=st.p_frame,
        p_restyle=st.p_restyle,
        p_number_words=st.p_number_words,
        max_words=c.max_words,
        language="extended",
    )
    return _prompt(text, variants, res.ids, pred.tags, pred, "attribute", None)


def _out_of_class(sc: DrawScene) -> Prompt | None:
    if sc.rng.random() < sc.cfg.p_nonsense:
        text = nonsense(sc.words)
        if "class" in infer_tags(text, sc.cfg.classes):
            return None
        return _prompt(text, (), (), infer_tags(text, sc.cfg.classes), None, "out_of_class", None)
    nouns = _NOUNS[(sc.cfg.phrasing, sc.cfg.classes)]
    noun = nouns[int(sc.rng.integers(len(nouns)))]
    atoms: tuple[Atom, ...] = ()
    extreme = None
    if sc.rng.random() < 0.55:
        # Where a thing is, not how it moves (a bench does not "move away").
        geometry = replace(sc.cfg, p_extreme=0.15, geometry_only=True)
        base = sample_predicate(fake_actor(sc), sc.rng, geometry)
        if base is not None:
            atoms, extreme = base.atoms[:2], base.extreme
    pred = Predicate(None, atoms, extreme)
    n = 1 if extreme is not None or sc.rng.random() < 0.6 else 2
    text, variants = render_plain(pred, n, sc.words, noun=noun, **_render(sc))
    variants = (f"ooc:{noun}", *variants)
    return _prompt(text, variants, (), infer_tags(text, sc.cfg.classes), None, "out_of_class", None)


def _unsatisfiable(sc: DrawScene) -> Prompt | None:
    forms, shares = zip(*UNSATISFIABLE_FORMS, strict=True)
    pred = forms[int(sc.rng.choice(len(forms), p=np.array(shares) / sum(shares)))](sc)
    if pred is None or not unsatisfiable(pred, sc.feats, sc.region):
        return None
    n = 1 if pred.extreme is not None or sc.rng.random() < 0.4 else 2
    text, variants = render_plain(pred, n, sc.words, **_render(sc))
    return _prompt(text, variants, (), pred.tags, pred, "unsatisfiable", None)


def _atom_of(g: ActorFeatures, sc: DrawScene) -> Atom | None:
    """An atom true of ``g`` (to be negated, or to cut a subset out of a set)."""
    kind = int(sc.rng.integers(5))
    if kind == 0:
        return depth_atom(g, sc.rng)
    if kind == 1:
        side = side_of(g)
        return OnSide(side) if side is not None else None
    if kind == 2:
        return MotionState(g.speed > MOVING_SPEED)
    if kind == 3:
        headings = [h for h in Heading if HeadingIs(h).holds(g, -1.0)]
        return HeadingIs(headings[int(sc.rng.integers(len(headings)))]) if headings else None
    v = math.floor(g.speed * 3.6 / 5) * 5 - 5
    return SpeedAbove(float(v), SpeedUnit.KMH) if v >= 5 else None


def _negation(sc: DrawScene) -> Prompt | None:
    f = sc.anchor()
    other = sc.anchor()
    atom = _atom_of(other, sc)
    if atom is None or atom.holds(f, 1.0) or negation_slot(atom, CLASS_KEYS[f.cls]) is None:
        return None
    base = sampled(sc, f, 1, extreme=sc.rng.random() < 0.5)
    if base is None:
        return None
    keep = tuple(a for a in base.atoms if a.family != atom.family)
    pred = Predicate(f.cls if sc.rng.random() < 0.9 else None, (*keep, Not(atom)), base.extreme)
    res = sc.analyse(pred)
    if not res.ids or not sc.ok(res):
        return None
    text, variants = render_negation(pred, len(res.ids), sc.words, **_render(sc))
    return _prompt(text, variants, res.ids, pred.tags, pred, "negation", None)


def _base_set(sc: DrawScene, minimum: int) -> tuple[Predicate, Resolution] | None:
    f = sc.anchor()
    base = sampled(sc, f, 1 if sc.rng.random() < 0.4 else 0, extreme=False)
    if base is None:
        return None
    res = sc.analyse(base)
    if len(res.ids) < minimum or not sc.ok(res):
        return None
    return base, res


def _exclusion(sc: DrawScene) -> Prompt | None:
    found = _base_set(sc, 2)
    if found is None:
        return None
    base, res = found
    if sc.rng.random() < 0.5:
        removed = Predicate(base.cls, base.atoms, _EXTREMES[int(sc.rng.integers(len(_EXTREMES)))])
    else:
        pick = res.ids[int(sc.rng.integers(len(res.ids)))]
        g = next(f for f in sc.feats if f.actor_id == pick)
        atom = _atom_of(g, sc)
        if atom is None or atom.family in {a.family for a in base.atoms}:
            return None
        removed = Predicate(base.cls, (*base.atoms, atom))
    expr = Exclusion(base, removed)
    out = sc.resolve(expr)
    if not out.ids or not sc.ok(out):
        return None
    n_removed = len(res.ids) - len(out.ids)
    text, variants = render_exclusion(expr, len(res.ids), n_removed, sc.words, **_render(sc))
    return _prompt(
        text, variants, out.ids, infer_tags(text, sc.cfg.classes), base, "exclusion", expr
    )


def _ordinal(sc: DrawScene) -> Prompt | None:
    if sc.rng.random() < P_CLASS_FREE_ORDINAL:
        base = Predicate(None)
        res = sc.analyse(base)
        extreme = (Extreme.NEAREST, Extreme.FARTHEST)[int(sc.rng.integers(2))]
        if len(res.ids) < 2 or not sc.ok(res):
            return None
    else:
        found = _base_set(sc, 2)
        if found is None:
            return None
        base, res = found
        extreme = _EXTREMES[int(sc.rng.integers(len(_EXTREMES)))]
    lateral = extreme in (Extreme.LEFTMOST, Extreme.RIGHTMOST)
    if lateral and any(isinstance(a, OnSide) for a in base.atoms):
        return None
    rank = int(sc.rng.integers(2, min(4, len(res.ids)) + 1))
    expr = Ordinal(base, extreme, rank)
    out = sc.resolve(expr)
    if not out.ids or not sc.ok(out):
        return None
    text, variants = render_ordinal(expr, sc.words, **_render(sc))
    return _prompt(text, variants, out.ids, infer_tags(text, sc.cfg.classes), base, "ordinal", expr)


def _reference(sc: DrawScene, r: ActorFeatures) -> Predicate | None:
    """A predicate that picks exactly ``r``, crisply (the simplest that does)."""
    cands = [Predicate(r.cls)]
    side = side_of(r)
    if side is not None:
        cands.append(Predicate(r.cls, (OnSide(side),)))
    cands.append(Predicate(r.cls, (MotionState(r.speed > MOVING_SPEED),)))
    cands += [Predicate(r.cls, (), e) for e in _EXTREMES]
    for pred in cands:
        res = sc.analyse(pred)
        if res.ids == (r.actor_id,) and not res.conflicts and res.crisp:
            return pred
    return None


def _relation(sc: DrawScene) -> Prompt | None:
    relation = list(Relation)[int(sc.rng.integers(len(Relation)))]
    if relation is Relation.BETWEEN:
        reference = Predicate(sc.anchor().cls)
        ref_ids = sc.analyse(reference).ids
        if len(ref_ids) != 2:
            return None
    else:
        r = sc.anchor()
        ref = _reference(sc, r)
        if ref is None:
            return None
        reference, ref_ids = ref, (r.actor_id,)
    refs = [f for f in sc.inside if f.actor_id in ref_ids]
    others = [f for f in sc.inside if f.actor_id not in ref_ids]
    if relation is not Relation.CLOSEST_TO:
        if (
            relation is Relation.BETWEEN
            and math.dist((refs[0].x, refs[0].y), (refs[1].x, refs[1].y)) < 4.0
        ):
            return None
        others = [f for f in others if relation_holds(relation, f, refs)]
    if not others:
        return None
    t = others[int(sc.rng.integers(len(others)))]
    target = Predicate(t.cls if sc.rng.random() < 0.85 else None)
    expr = Related(target, relation, reference)
    out = sc.resolve(expr)
    if not out.ids or not sc.ok(out):
        return None
    text, variants = render_relation(expr, len(out.ids), sc.words, **_render(sc))
    return _prompt(
        text, variants, out.ids, infer_tags(text, sc.cfg.classes), target, "relation", expr
    )


def _count(sc: DrawScene) -> Prompt | None:
    f = fake_actor(sc) if sc.rng.random() < 0.25 else sc.anchor()
    base = sampled(sc, f, 2, extreme=False)
    if base is None:
        return None
    expr = Count(base)
    res = sc.resolve(expr)
    if res.conflicts or not (res.crisp if res.ids else unsatisfiable(base, sc.feats, sc.region)):
        return None
    text, variants = render_count(expr, sc.words, **_render(sc))
    return _prompt(text, variants, res.ids, base.tags, base, "count", expr)


_SAMPLERS: dict[str, Callable[[DrawScene], Prompt | None]] = {
    "attribute": _attribute,
    "out_of_class": _out_of_class,
    "unsatisfiable": _unsatisfiable,
    "negation": _negation,
    "exclusion": _exclusion,
    "ordinal": _ordinal,
    "relation": _relation,
    "count": _count,
}


def generate_extended(
    actors: Sequence[Actor],
    rng: np.random.Generator,
    n: int,
    *,
    region: ReferableRegion,
    config: PromptConfig,
) -> list[Prompt]:
    """Up to ``n`` distinct prompts of every family (module docstring); none when no actor is
    referable. Deterministic for a given ``rng`` state."""
    feats = actor_features(actors)
    inside = [f for f in feats if region.contains(f)]
    if not inside or n == 0:
        return []
    style = Style(
        config.p_count_word,
        config.p_adjective,
        config.p_frame,
        config.p_restyle,
        config.p_number_words,
    )
    words = np.random.default_rng(int(rng.integers(2**63)))
    sc = DrawScene(feats, inside, region, rng, words, config, style)
    rates = np.array([max(0.0, 1.0 - sum(config.family_rates)), *config.family_rates])
    rates = rates / rates.sum()
    out: list[Prompt] = []
    seen: set[str] = set()
    budget = n * config.tries_per_prompt
    family = ""
    misses = FAMILY_TRIES
    while budget > 0 and len(out) < n:
        budget -= 1
        if misses >= FAMILY_TRIES:
            family = FAMILIES[int(rng.choice(len(FAMILIES), p=rates))]
            misses = 0
        prompt = _SAMPLERS[family](sc)
        key = prompt.text.lower().rstrip(".!?") if prompt is not None else ""
        if (
            prompt is None
            or key in seen
            or len(prompt.text.split()) > config.max_words
            or too_wide(prompt.variants, config.classes)
        ):
            misses += 1
            continue
        seen.add(key)
        out.append(prompt)
        misses = FAMILY_TRIES
    return out
