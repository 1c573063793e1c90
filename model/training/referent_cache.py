"""The second stage of the referent path (``--freeze-scene``): scenes encoded once, prompts banked.

Every training scene is encoded once by the frozen detector (:func:`cache_scenes`), its detections
are matched to its actors (:func:`match_detections`), its prompts (generated, or given with a real
root) are encoded once by the frozen text encoder (:class:`TextBank`), and each step then scores
some of them per scene (:func:`cached_referent_step`) at a small fraction of a joint step's cost.
Its candidates are exactly what inference sees: the detector's own boxes and scores, misses and
false detections included.

Labelled views (issue 37): the same checkpoint also grounds over a frame's labelled boxes
(``model.evaluate --candidates labels``, the app's "Labelled boxes", the Annotate tab's
sentence-first flow), where a candidate's class is its label's and its score certain
(:mod:`model.core.labelled`). So each scene is also cached as that kind of candidate set
(:attr:`CachedScene.labelled`: its actors' boxes as the labelled boxes, the detector's other
proposals as context), and a step draws a scene's labelled view with
``TrainConfig.labelled_views``. Where the detector is wrong (a sensor it never saw, a person it
does not see) the features it pools at a labelled box say "background" or "another class"; to
teach the stage that the label decides, :func:`shift_evidence` gives some labelled boxes the
pooled map features of another candidate of the scene (another object, or clutter the detector
proposed), keeping their own explicit evidence (point counts, radar motion) and geometry.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch

from model.core.candidates import SceneCandidates
from model.core.labelled import LabelledBoxes
from model.grounding.referent import referent_head
from model.head.losses import LossTerms
from model.nets.text import encode_minilm_batched, pad_features
from model.referent.candidates import LIDAR_EVIDENCE, RADAR_EVIDENCE
from model.tpcnet import TPCNet
from model.training.referent_step import (
    ReferentLoss,
    ReferentTrainConfig,
    _per_item,
    frame_prompts,
    in_grid_actors,
    model_frame,
)
from model.training.scene_store import FrozenStore, scene_key
from scenes.datasets.frames import FrameDataset, FrameItem
from scenes.geometry.actors import Actor
from scenes.geometry.boxes import match_by_centre
from scenes.geometry.classes import VOD, ClassSet
from scenes.language.prompts import PromptConfig


@dataclass(frozen=True)
class CachedScene:
    """A training scene encoded once by the frozen detector, with its bank of prompts.

    Attributes:
        candidates: The detector's candidates (tensors detached, on the CPU).
        actor_ids: ``(K,)`` the actor each candidate detects, -1 for a false detection.
        prompts: Generated prompts with at least one detected referent.
        targets: Per prompt, ``(K,)`` float32: 1 where the candidate is a referent.
        answerable: A labelled view: its first ``answerable`` candidates are the labelled boxes
            (the rest is context); None: the detector's candidates.
        labelled: The same scene with its actors' boxes as labelled candidates (module
            docstring); None when not cached.
    """

    candidates: SceneCandidates
    actor_ids: np.ndarray
    prompts: tuple[str, ...]
    targets: tuple[np.ndarray, ...]
    answerable: int | None = None
    labelled: CachedScene | None = None


def _arrays_state(c: SceneCandidates) -> dict:
    arrays = {"boxes": c.boxes, "labels": c.labels, "scores": c.scores}
    return {
        **{k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in arrays.items()},
        "geometry": c.geometry,
        "fused": c.fused,
        "lidar": c.lidar,
        "radar": c.radar,
    }


def _candidates(d: dict) -> SceneCandidates:
    return SceneCandidates(
        d["boxes"].numpy(),
        d["labels"].numpy(),
        d["scores"].numpy(),
        d["geometry"],
        d["fused"],
        d["lidar"],
        d["radar"],
    )


@dataclass(frozen=True)
class EncodedScene:
    """A scene as the frozen detector encodes it, before any prompt (:func:`encode_scene`):
    what :mod:`model.training.scene_store` keeps, since it depends on the scene and the detector
    only (the prompts are drawn again by each run, cheaply).

    Attributes:
        objects: The detector's candidates (on the CPU).
        ids: ``(K,)`` the actor each candidate detects, -1 for a false detection.
        labelled: The labelled view's candidates and their actor ids (-1: context), or None.
    """

    objects: SceneCandidates
    ids: np.ndarray
    labelled: tuple[SceneCandidates, np.ndarray] | None = None

    def state(self) -> dict:
        """Tensors, lists and numbers only (:meth:`from_state` reads it back exactly)."""
        view = None
        if self.labelled is not None:
            objects, ids = self.labelled
            view = {**_arrays_state(objects), "ids": torch.from_numpy(ids.copy())}
        return {
            **_arrays_state(self.objects),
            "ids": torch.from_numpy(self.ids.copy()),
            "labelled": view,
        }

    @classmethod
    def from_state(cls, d: dict) -> EncodedScene:
        view = d["labelled"]
        labelled = None if view is None else (_candidates(view), view["ids"].numpy())
        return cls(_candidates(d), d["ids"].numpy(), labelled)


def encode_scene(model: TPCNet, item: FrameItem, labelled: bool) -> EncodedScene:
    """``item`` (as ``model`` sees it) encoded by the frozen detector (:func:`scene_views`), its
    detections matched to its actors (:func:`match_detections`)."""
    objects, view = scene_views(model, item.lidar, item.radar, item.actors, labelled)
    ids = match_detections(objects.boxes, objects.labels, item.actors, model.cfg.class_set)
    extra = None if view is None else (_on_cpu(view[0]), view[1])
    return EncodedScene(_on_cpu(objects), ids, extra)


def _encoded(
    model: TPCNet, item: FrameItem, labelled: bool, store: FrozenStore | None
) -> EncodedScene:
    """:func:`encode_scene`, read back from ``store`` where an earlier run kept it, and kept there
    when encoded here."""
    if store is None:
        return encode_scene(model, item, labelled)
    key = scene_key(item, labelled)
    state = store.scenes.load(key)
    if state is not None:
        return EncodedScene.from_state(state)
    encoded = encode_scene(model, item, labelled)
    store.scenes.save(key, encoded.state())
    return encoded


def match_detections(
    boxes: np.ndarray, labels: np.ndarray, actors: Sequence[Actor], classes: ClassSet = VOD
) -> np.ndarray:
    """Actor id ``(K,)`` of each detection (-1: none): detections in the given (score) order take
    the nearest free actor of their class within its class's
    :attr:`scenes.geometry.classes.ObjectClass.match_distance` of the BEV centre
    (:func:`scenes.geometry.boxes.match_by_centre`); ``labels`` and the actors' classes index
    ``classes`` (the model's; actors of other classes match nothing)."""
    actors = [a for a in actors if a.cls in classes]
    if not actors:
        return np.full(len(boxes), -1, dtype=np.int64)
    targets = np.stack([a.box for a in actors])
    target_labels = np.array([classes.index(a.cls) for a in actors], dtype=np.int64)
    limits = np.array(classes.match_distances)
    index = match_by_centre(boxes, labels, targets, target_labels, limits)
    ids = np.array([a.actor_id for a in actors], dtype=np.int64)
    return np.where(index >= 0, ids[np.maximum(index, 0)], -1)


def _on_cpu(objects: SceneCandidates) -> SceneCandidates:
    return replace(
        objects,
        geometry=objects.geometry.cpu(),
        fused=objects.fused.cpu(),
        lidar=None if objects.lidar is None else objects.lidar.cpu(),
        radar=None if objects.radar is None else objects.radar.cpu(),
    )


def _cached(
    objects: SceneCandidates,
    ids: np.ndarray,
    prompts: Sequence[tuple[str, tuple[int, ...]]],
    answerable: int | None = None,
) -> CachedScene:
    """A cached view of ``objects`` (candidate actor ids ``ids (K,)``) with the prompts it can
    answer: one that refers to nothing (the empty answer is an answer: things outside the
    classes, attributes nothing here has) or to a candidate."""
    usable = [(text, refs) for text, refs in prompts if not refs or np.isin(ids, refs).any()]
    return CachedScene(
        objects,
        ids,
        tuple(text for text, _ in usable),
        tuple(np.isin(ids, refs).astype(np.float32) for _, refs in usable),
        answerable,
    )


def scene_views(
    model: TPCNet, lidar: np.ndarray, radar: np.ndarray, actors: Sequence[Actor], labelled: bool
) -> tuple[SceneCandidates, tuple[SceneCandidates, np.ndarray] | None]:
    """One scene's candidates as inference builds them from the detector's proposals and, with
    ``labelled``, over labelled boxes too, from one pass of the frozen encoder
    (:meth:`model.grounding.referent.ReferentGrounding.encode_views`): the metric-class ``actors``
    whose anchor lies in the head grid are the labelled boxes (their exact boxes, as a label gives
    them), the detector's other proposals the context. The labelled view comes with its
    candidates' actor ids ``(K,)`` (-1 for context); it is None without ``labelled`` or when no
    actor is in the grid."""
    kept = in_grid_actors(actors, model) if labelled else []
    boxes = np.stack([a.box for a in kept]) if kept else None
    classes = model.cfg.class_set
    labels = [classes.index(a.cls) for a in kept]
    views = (None, LabelledBoxes(boxes, labels, classes)) if kept else (None,)
    lidar_t = model.scene.clouds([lidar], 1, "lidar")
    radar_t = model.scene.clouds([radar], 1, "radar")
    with torch.no_grad():
        features = referent_head(model).encode_views(model.scene, lidar_t, radar_t, views)
    objects = [f.objects for f in features]
    assert all(o is not None for o in objects)
    if not kept:
        return objects[0], None
    ids = np.full(len(objects[1]), -1, dtype=np.int64)
    ids[: len(kept)] = [a.actor_id for a in kept]
    return objects[0], (objects[1], ids)


def shift_evidence(scene: CachedScene, rng: np.random.Generator, share: float) -> CachedScene:
    """A labelled view whose labelled boxes each, with probability ``share``, read the pooled map
    features (fused, and the LiDAR and radar branches' pooled part) of another candidate of the
    scene drawn at random, as on a frame where the detector sees something else there (module
    docstring); their geometry (class one-hot from the label, score), point counts and radar
    motion stay their own. A detector view, or ``share`` 0, comes back as is."""
    n = scene.answerable or 0
    k = len(scene.candidates)
    if n == 0 or k < 2 or share <= 0:
        return scene
    moved = np.flatnonzero(rng.random(n) < share)
    if not len(moved):
        return scene
    donors = rng.integers(0, k - 1, size=len(moved))
    donors = donors + (donors >= moved)  # another candidate than itself
    src = torch.arange(k)
    src[torch.from_numpy(moved)] = torch.from_numpy(donors)
    cands = scene.candidates

    def pooled(t: torch.Tensor | None, evidence: int) -> torch.Tensor | None:
        if t is None:
            return None
        out = t.clone()
        width = t.shape[1] - evidence
        out[:, :width] = t[src, :width]
        return out

    shifted = replace(
        cands,
        fused=cands.fused[src],
        lidar=pooled(cands.lidar, LIDAR_EVIDENCE),
        radar=pooled(cands.radar, RADAR_EVIDENCE),
    )
    return replace(scene, candidates=shifted)


@dataclass
class TextBank:
    """Frozen-encoder token features of every banked prompt: ``text -> (tokens, numbers,
    truncated)`` (tokens kept as float16 to halve the memory)."""

    entries: dict

    def features(self, texts: Sequence[str], device: torch.device):
        """:class:`model.nets.text.TextFeatures` of ``texts`` (all in the bank)."""
        return pad_features([self.entries[t] for t in texts], device)


def cache_scenes(
    model: TPCNet,
    dataset: FrameDataset,
    prompts_per_scene: int,
    seed: int = 0,
    progress: bool = True,
    label_prompts: int = 0,
    known: TextBank | None = None,
    prompt_config: PromptConfig | None = None,
    labelled: bool = False,
    given_variants: int = 0,
    store: FrozenStore | None = None,
) -> tuple[list[CachedScene], TextBank]:
    """Encode every scene of ``dataset`` with the frozen model, generate ``prompts_per_scene``
    prompts per scene (labels source: take its given prompts, plus ``label_prompts`` from its
    labelled boxes, :func:`frame_prompts`) and encode them with the frozen text encoder (module
    docstring). A ``dataset`` that flips every frame gives the mirrored views of the scenes.
    Prompts already in ``known`` (e.g. the other view's bank) are not encoded again; the bank
    returned holds only the new ones. ``prompt_config``: the generator's settings
    (:attr:`model.training.config.PromptDraw.config`; default: the base
    prompts in the training phrasings). ``labelled``: also cache each scene's labelled view
    (:attr:`CachedScene.labelled`, :func:`scene_views`), with the same prompts.
    ``given_variants``: rewordings banked beside each given prompt (:func:`frame_prompts`).
    ``store``: scenes and prompt features kept on disk by earlier runs are read back, and what
    is encoded here is kept (:mod:`model.training.scene_store`)."""
    from tqdm import tqdm

    model.eval()
    pcfg = prompt_config or PromptConfig()
    scenes = []
    bar = tqdm(range(len(dataset)), desc="cache scenes", disable=not progress)
    with torch.no_grad():
        for i in bar:
            item = model_frame(model, dataset[i])
            encoded = _encoded(model, item, labelled, store)
            if store is not None:
                bar.set_postfix(stored=store.scenes.hits, refresh=False)
            rng = np.random.default_rng((seed, 11, i))
            prompts = frame_prompts(
                item, rng, prompts_per_scene, pcfg, label_prompts, given_variants
            )
            view = encoded.labelled
            extra = None if view is None else _cached(*view, prompts, int((view[1] >= 0).sum()))
            scenes.append(replace(_cached(encoded.objects, encoded.ids, prompts), labelled=extra))
    done = {} if known is None else known.entries
    views = [v for s in scenes for v in (s, s.labelled) if v is not None]
    texts = [t for t in dict.fromkeys(t for v in views for t in v.prompts) if t not in done]
    entries = {} if store is None else store.texts.load(texts)
    texts = sorted((t for t in texts if t not in entries), key=len)  # batches of like length
    max_tokens = model.cfg.text.max_tokens
    chunk = 256
    for start in tqdm(
        range(0, len(texts), chunk), desc="encode prompts", disable=not progress, unit="chunk"
    ):
        part = texts[start : start + chunk]
        new = {}
        for text, (tok, num, trunc) in zip(
            part, encode_minilm_batched(part, max_tokens, 64), strict=True
        ):
            new[text] = (tok.half(), num, trunc)
        if store is not None:
            store.texts.save(new)
        entries.update(new)
    return scenes, TextBank(entries)


def cached_referent_step(
    model: TPCNet,
    scenes: Sequence[CachedScene],
    bank: TextBank,
    rng: np.random.Generator | Sequence[np.random.Generator],
    cfg: ReferentTrainConfig,
) -> ReferentLoss:
    """Referent loss on cached scenes, ``cfg.prompts.per_scene`` banked prompts drawn per scene
    (only the referent stage learns; ``rng`` as in :func:`referent_step`). Undetected referents
    cannot be answered and are not in a prompt's target."""
    device = model.device
    chosen, texts, rows, targets = [], [], [], []
    for scene, scene_rng in zip(scenes, _per_item(rng, len(scenes)), strict=True):
        if not len(scene.candidates) or not scene.prompts:
            continue
        k = min(cfg.prompts.per_scene, len(scene.prompts))
        picks = scene_rng.choice(len(scene.prompts), size=k, replace=False)
        index = len(chosen)
        chosen.append(scene.candidates)
        for j in picks:
            texts.append(scene.prompts[j])
            rows.append(index)
            targets.append(scene.targets[j])
    zero = torch.zeros((), device=device)
    if not texts:
        return ReferentLoss(zero, LossTerms(zero, zero, zero), zero, zero, 0)
    text = bank.features(texts, device)
    bce, listwise = referent_head(model).prompt_losses(chosen, rows, text, targets)
    total = cfg.referent_weight * (bce + cfg.listwise_weight * listwise)
    return ReferentLoss(total, LossTerms(zero, zero, zero), bce, listwise, len(texts))


__all__ = [
    "CachedScene",
    "EncodedScene",
    "TextBank",
    "cache_scenes",
    "cached_referent_step",
    "encode_scene",
    "match_detections",
    "scene_views",
    "shift_evidence",
]
