"""Baselines that tell grounding from detection, scored beside the model (``model.evaluate``).

- **Language-blind oracle** (:func:`oracle_boxes`): a perfect detector that reads only the class
  noun. For each prompt it returns every ground-truth actor of the named class inside the annotated
  region (:data:`scenes.language.prompts.DEFAULT_REGION`, tested on :meth:`ActorFeatures.of`), each with
  score 1. The actors are the frame's full list from the sample's sidecar
  (``Talk2RadarRoot.load(id).meta.actors``), not only the referents of ``label_2``, less those the
  sidecar lists as unsensed (:func:`unsensed_ids`: no LiDAR or radar return, so no prompt refers to
  them and no detector could find them; counting them would only weaken the baseline).
- **Class noun** (:func:`class_noun_prompt`): the same model, on the same encoded scene, given only
  "the cars" / "the pedestrians" / "the cyclists" ("the objects" for a prompt that names no class).

The named class (:func:`named_class`) is the referents' class when the prompt names a class (its
``class`` tag) and all its referents share that class (always so for generated prompts); otherwise
(no class word, mixed or no referents) every class counts. A prompt without a class word therefore
gives the oracle no class either: it sees only what the words name.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from model.evaluation.grounding import CLASS_TAG, PromptBoxes
from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.actors import Actor
from scenes.geometry.classes import object_class
from scenes.language.prompts import DEFAULT_REGION, ActorFeatures, ReferableRegion

NO_CLASS_NOUN = "the objects"
"""The class-noun prompt of a prompt that names no class."""


def named_class(tags: Iterable[str], referent_classes: Sequence[str]) -> str | None:
    """The class a prompt names: its referents' single class when it has the ``class`` tag, else
    None (every class)."""
    distinct = set(referent_classes)
    if CLASS_TAG in set(tags) and len(distinct) == 1:
        return next(iter(distinct))
    return None


def class_noun_prompt(cls: str | None) -> str:
    """ "the " and the class's plural (:attr:`scenes.geometry.classes.ObjectClass.plural`:
    "the cars", "the pedestrians", "the cyclists", "the trucks", "the traffic cones", ...), or
    "the objects" for None; ValueError for a name of no class set."""
    if cls is None:
        return NO_CLASS_NOUN
    try:
        return f"the {object_class(cls).plural}"
    except ValueError as exc:
        raise ValueError(f"no class noun for {cls!r}: {exc}") from None


def unsensed_ids(meta: SampleMeta, source: str = "<meta>") -> frozenset[int]:
    """The actor ids ``scenes.synth`` records as seen by neither sensor
    (``meta.extra["unsensed_actor_ids"]``; empty where the sidecar has no such list)."""
    raw = meta.extra.get("unsensed_actor_ids", ())
    if not isinstance(raw, list | tuple) or not all(
        isinstance(i, int) and not isinstance(i, bool) for i in raw
    ):
        raise ValueError(
            f"{source}: extra.unsensed_actor_ids must be a list of integers, got {raw!r}"
        )
    return frozenset(raw)


def oracle_boxes(
    actors: Sequence[Actor],
    cls: str | None,
    region: ReferableRegion = DEFAULT_REGION,
    exclude: Iterable[int] = (),
) -> PromptBoxes:
    """Every actor of class ``cls`` (None: any class) inside ``region``, score 1.

    Args:
        actors: All actors of the frame (LiDAR frame boxes, sidecar order).
        cls: The named class, or None.
        region: Where actors can be referents.
        exclude: Actor ids left out (the unsensed ones, :func:`unsensed_ids`).

    Returns:
        ``(K, 7)`` LiDAR-frame boxes with their classes and scores of 1, in actor order.
    """
    skip = frozenset(exclude)
    kept = [
        a
        for a in actors
        if (cls is None or a.cls == cls)
        and a.actor_id not in skip
        and region.contains(ActorFeatures.of(a))
    ]
    boxes = np.array([a.box for a in kept], dtype=np.float64).reshape(-1, 7)
    return PromptBoxes.make(boxes, [a.cls for a in kept], source="oracle")
