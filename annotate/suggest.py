"""Suggest a Talk2Radar-style prompt for the boxes of a draft.

The boxes of the draft are the referents; the other objects of the scene (ground-truth actors of a
synthetic frame, the model's predictions, the labels of a real frame) are the distractors the
sentence must exclude. Both become :class:`scenes.geometry.actors.Actor` s and
:func:`scenes.language.prompts.describe` finds the simplest predicate that selects exactly the referents,
rendered with the same phrasing rules as the synthetic prompts.

Velocities. A scene object may carry a known ground velocity (a synthetic actor). A draft box
takes the velocity of the scene object it coincides with (centre within ``match_distance``, nearest
first, one box per object); otherwise, and for scene objects without a velocity, the velocity is
estimated from the radar points in the box (:func:`annotate.evidence.estimate_velocity`: the mean
compensated radial velocity along the box heading). With no radar point the object is taken as
stationary. Scene objects that coincide with a draft box are the same object and are not also
distractors.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from annotate.evidence import EvidenceConfig, box_evidence, estimate_velocity
from scenes.frame import Sample
from scenes.geometry.actors import Actor
from scenes.geometry.classes import VOD, ClassSet
from scenes.language.prompts import DEFAULT_REGION, Predicate, ReferableRegion, describe


@dataclass(frozen=True)
class SceneObject:
    """An object of the scene: ``box (7,)`` LiDAR frame, class, ground velocity ``(2,)`` if known."""

    box: tuple[float, ...]
    cls: str
    velocity: tuple[float, float] | None = None

    @staticmethod
    def of(actor: Actor) -> SceneObject:
        """A scene object with the actor's known velocity."""
        return SceneObject(
            tuple(float(v) for v in actor.box),
            actor.cls,
            (float(actor.velocity[0]), float(actor.velocity[1])),
        )


@dataclass(frozen=True)
class SuggestConfig:
    """Parameters of :func:`suggest_prompt`.

    Attributes:
        match_distance: A scene object whose BEV centre lies within this distance (m) of a draft
            box is the same object.
        region: Where referents may be (default: the synthetic prompts' referable region).
        evidence: Radar margins for the velocity estimate.
        max_words: Longest sentence.
        classes: The classes a sentence may name (the served model's class set): a draft box of
            another class cannot be described, a scene object of another class is left out.
    """

    match_distance: float = 1.0
    region: ReferableRegion = DEFAULT_REGION
    evidence: EvidenceConfig = field(default_factory=EvidenceConfig)
    max_words: int = 22
    classes: ClassSet = VOD


@dataclass(frozen=True)
class SceneActors:
    """Draft boxes and scene objects as actors: ids ``0..K-1`` are the draft boxes, in order."""

    referents: tuple[Actor, ...]
    distractors: tuple[Actor, ...]

    @property
    def all(self) -> tuple[Actor, ...]:
        return self.referents + self.distractors


@dataclass(frozen=True)
class Suggestion:
    """A suggested prompt.

    Attributes:
        text: The sentence, or None when none could be made.
        tags: Its type tags (``class``, ``depth``, ``velocity``, ``motion``, ``position``).
        reason: Why there is no sentence (None when there is one).
        actors: The actors the sentence was resolved over.
        predicate: The predicate the sentence says (``scenes.language.prompts.resolve`` of it over
            ``actors.all`` gives exactly the draft boxes' ids ``0..K-1``).
    """

    text: str | None
    tags: frozenset[str] = frozenset()
    reason: str | None = None
    actors: SceneActors | None = None
    predicate: Predicate | None = field(default=None, repr=False)


def _as_objects(scene: Sequence[SceneObject | Actor]) -> list[SceneObject]:
    return [SceneObject.of(o) if isinstance(o, Actor) else o for o in scene]


def scene_actors(
    boxes: np.ndarray,
    classes: Sequence[str],
    scene: Sequence[SceneObject | Actor],
    radar: np.ndarray | None,
    config: SuggestConfig | None = None,
) -> SceneActors:
    """Draft boxes ``(K, 7)`` and scene objects as actors with ground velocities (module doc).

    Scene objects of other classes than ``config.classes`` or with a non-positive size are left
    out (they cannot be referred to).

    Raises:
        ValueError: A draft box has a class outside ``config.classes`` or a non-positive size.
    """
    cfg = config if config is not None else SuggestConfig()
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(b) != len(classes):
        raise ValueError(f"{len(b)} boxes but {len(classes)} class names")
    objects = [
        o
        for o in _as_objects(scene)
        if o.cls in cfg.classes and np.all(np.asarray(o.box, dtype=np.float64)[3:6] > 0)
    ]
    radar_arr = np.zeros((0, 7)) if radar is None else np.asarray(radar, dtype=np.float64)
    # Greedy one-to-one matching of draft boxes to scene objects by BEV centre distance.
    matched: dict[int, int] = {}
    if objects and len(b):
        centres = np.array([o.box[:2] for o in objects], dtype=np.float64)
        dist = np.linalg.norm(b[:, None, :2] - centres[None], axis=-1)
        for flat in np.argsort(dist, axis=None):
            i, j = np.unravel_index(flat, dist.shape)
            if dist[i, j] > cfg.match_distance:
                break
            if int(i) not in matched and int(j) not in matched.values():
                matched[int(i)] = int(j)
    others = [o for j, o in enumerate(objects) if j not in matched.values()]
    all_boxes = np.concatenate(
        [b, np.array([o.box for o in others], dtype=np.float64).reshape(-1, 7)]
    )
    evidence = box_evidence(all_boxes, np.zeros((0, 4)), radar_arr, cfg.evidence)

    def velocity(k: int, known: tuple[float, float] | None) -> np.ndarray:
        if known is not None:
            return np.asarray(known, dtype=np.float64)
        return estimate_velocity(all_boxes[k], evidence[k].mean_radial_velocity)

    referents = []
    for i, cls in enumerate(classes):
        if str(cls) not in cfg.classes:
            raise ValueError(
                f"box {i + 1} of {len(b)}: class {str(cls)!r} is not one of {cfg.classes.names}"
            )
        known = objects[matched[i]].velocity if i in matched else None
        try:
            referents.append(Actor(i, str(cls), b[i], velocity(i, known)))
        except ValueError as exc:
            raise ValueError(f"box {i + 1} of {len(b)}: {exc}") from exc
    distractors = [
        Actor(len(b) + j, o.cls, np.asarray(o.box), velocity(len(b) + j, o.velocity))
        for j, o in enumerate(others)
    ]
    return SceneActors(tuple(referents), tuple(distractors))


def suggest_prompt(
    boxes: np.ndarray,
    classes: Sequence[str],
    scene: Sequence[SceneObject | Actor],
    radar: np.ndarray | None,
    rng: np.random.Generator,
    config: SuggestConfig | None = None,
) -> Suggestion:
    """A sentence that refers to exactly the draft boxes among the scene's objects.

    Args:
        boxes: ``(K, 7)`` the draft's boxes, LiDAR frame.
        classes: Their classes.
        scene: The other objects of the frame (distractors), with or without velocities.
        radar: ``(M, 7)`` radar points in the LiDAR frame, for velocities (None: none known).
        rng: Draws the phrasing (same seed, same sentence).

    Returns:
        A :class:`Suggestion`; ``text`` is None with a ``reason`` when no sentence fits.
    """
    cfg = config if config is not None else SuggestConfig()
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(b) == 0:
        return Suggestion(None, reason="add the boxes the prompt should refer to first")
    try:
        actors = scene_actors(b, classes, scene, radar, cfg)
    except ValueError as exc:
        return Suggestion(None, reason=f"cannot describe the boxes: {exc}")
    outside = [a.actor_id + 1 for a in actors.referents if not cfg.region.contains(a)]
    if outside:
        return Suggestion(
            None,
            reason=f"box(es) {', '.join(map(str, outside))} lie outside the region prompts speak "
            "about (0-50 m ahead, inside the camera's field of view)",
            actors=actors,
        )
    prompt = describe(actors.referents, actors.all, rng, region=cfg.region, max_words=cfg.max_words)
    if prompt is None:
        return Suggestion(
            None,
            reason="no sentence of the prompt language singles out exactly these boxes "
            "(other objects share every attribute, or one stands too close to the region's "
            "edge); write the prompt by hand",
            actors=actors,
        )
    return Suggestion(prompt.text, prompt.tags, None, actors, prompt.predicate)


def scene_objects(sample: Sample) -> list[Actor | SceneObject]:
    """The objects of a frame a suggested prompt must tell the draft boxes apart from: the
    sidecar's actors (with velocities) when the sample has one, else its labelled boxes."""
    if sample.meta is not None and sample.meta.actors:
        return list(sample.meta.actors)
    return [
        SceneObject(tuple(float(v) for v in box), cls)
        for box, cls in zip(np.asarray(sample.boxes).reshape(-1, 7), sample.classes, strict=True)
    ]
