"""Grounding metrics: does the answer to a prompt hold exactly the objects the prompt refers to?

The official mAP (:mod:`model.evaluation.metrics`) pools every detection of a split and ranks them by score, so
a detector that ignores every word but the class noun scores well on it. These metrics judge each
prompt's answer on its own, as the referring-expression literature does (ScanRefer, Mono3DVG).

All boxes are ``(K, 7)`` float arrays ``x, y, z, l, w, h, yaw`` in the LiDAR frame (x forward,
y left, z up, metres; ``z`` at the geometric centre, ``yaw`` counter-clockwise about +z), compared
by the exact 3D IoU of :func:`scenes.geometry.boxes.iou3d`. A predicted box can only match a referent of the
same class. Every figure of a summary is a percentage (0..100) like the official mAP.

Per prompt:

- **Acc@0.25 / Acc@0.5**: the top-scored predicted box (whatever its score) is a hit when its 3D IoU
  with some referent of its class is *strictly greater* than 0.25 / 0.5. When several boxes share
  the top score (the oracle baseline scores every box 1) the hit counts the expected value of a
  uniformly random pick among them: hits among the tied boxes / number tied. No predicted box: a
  miss. A prompt without referents is left out of Acc (it has no box to point at).
- **Set metrics at the operating threshold** ``t``: the predicted boxes with ``score >= t`` (the
  decoder's rule) are matched one-to-one to the referents, greedily in descending score order: each
  takes the free referent of its class with the largest 3D IoU strictly above the class's official
  minimum overlap (:data:`model.evaluation.metrics.MIN_OVERLAPS`, 3D: 0.5 Car, 0.25 Pedestrian / Cyclist;
  "strictly above" as the official protocol). With ``TP`` matches, ``P`` kept boxes and ``R``
  referents: precision ``TP / P``, recall ``TP / R`` (0 where the denominator is 0), F1
  ``2 TP / (P + R)`` (1 where ``P = R = 0``: nothing asked, nothing answered); the prompt is an
  **exact set** when ``TP = P = R`` (every referent matched and no extra box).

Over a set of prompts (:class:`GroundingSummary`): Acc is the mean hit over prompts with referents;
precision / recall / F1 are **micro-averaged over boxes** (summed TP, P, R); **set F1 is the mean of
the per-prompt F1** (each prompt weighs the same, however many referents it has); exact-set is the
share of prompts answered with exactly their referent set. :func:`grounding_metrics` also splits
the prompts by type tag (:data:`GROUNDING_TYPES`, a prompt in each of its tags), by class-only vs
attribute (any tag besides ``class``) and by single vs multiple referents.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from model.evaluation.metrics import MIN_OVERLAPS
from model.evaluation.report_file import BY_GROUP, BY_TYPE, OVERALL, THRESHOLD, SummaryFigures
from scenes.geometry.boxes import iou3d
from scenes.geometry.classes import VOD

GROUNDING_TYPES: tuple[str, ...] = ("class", "depth", "velocity", "motion", "position")
"""Prompt type tags the metrics are split by (``scenes.language.prompts`` tags)."""

CLASS_TAG = "class"
"""The tag of a prompt that names a class; every other tag names an attribute."""

ACC_IOUS: tuple[float, float] = (0.25, 0.5)
"""3D IoU thresholds of Acc@0.25 and Acc@0.5."""

CandidateSource = Literal["detector", "labels"]
"""What the referent stage chooses the answer among: the detector's proposals, or the frame's
labelled boxes (grounding apart from detection; ``model.evaluate --candidates``)."""

CLASS_GROUPS: tuple[str, ...] = ("vod_classes", "beyond_vod")
"""Prompt groups by the referents' classes: every referent of the ``vod`` set's classes (Car,
Pedestrian, Cyclist), or every referent of a class beyond them (a ``nuscenes`` model's trucks,
buses, trailers, construction vehicles, motorcycles, bicycles, cones, barriers); a prompt with
referents of both, or none, is in neither. Only where some referent is of a class beyond the
three (a ``vod`` evaluation's figures and report files are as they were)."""

GROUPS: tuple[str, ...] = ("class_only", "attribute", "single", "multiple", "empty", *CLASS_GROUPS)
"""Prompt groups: no attribute tag / some attribute tag; one referent / two or more / none (the
right answer is no box: things outside the classes, attributes nothing in the scene has; its
exact-set share is the share of such prompts answered with no box); then :data:`CLASS_GROUPS`."""


def _min_overlap(cls: str, source: str) -> float:
    """The class's official 3D minimum overlap (any class set's class)."""
    if cls not in MIN_OVERLAPS:
        raise ValueError(f"{source}: unknown class {cls!r} (expected one of {tuple(MIN_OVERLAPS)})")
    return MIN_OVERLAPS[cls].box3d


@dataclass(frozen=True)
class PromptBoxes:
    """The boxes of one prompt: an answer or its referents.

    Attributes:
        boxes: ``(K, 7)`` float64, LiDAR frame (see the module doc).
        classes: ``K`` class names (``Car``, ``Pedestrian``, ``Cyclist``).
        scores: ``(K,)`` float64 confidences (1 for ground truth and the oracle).
    """

    boxes: np.ndarray
    classes: tuple[str, ...]
    scores: np.ndarray

    @staticmethod
    def make(
        boxes: np.ndarray,
        classes: Sequence[str],
        scores: np.ndarray | Sequence[float] | None = None,
        source: str = "<boxes>",
    ) -> PromptBoxes:
        """Validated boxes (``scores`` None: all 1); errors name ``source`` and the field."""
        arr = np.asarray(boxes, dtype=np.float64)
        if arr.size == 0:
            arr = arr.reshape(0, 7)
        if arr.ndim != 2 or arr.shape[1] != 7:
            raise ValueError(f"{source}: boxes must have shape (K, 7), got {arr.shape}")
        names = tuple(str(c) for c in classes)
        if len(names) != len(arr):
            raise ValueError(f"{source}: {len(names)} classes for {len(arr)} boxes")
        for name in names:
            _min_overlap(name, source)
        sc = np.ones(len(arr)) if scores is None else np.asarray(scores, dtype=np.float64)
        if sc.shape != (len(arr),):
            raise ValueError(f"{source}: scores must have shape ({len(arr)},), got {sc.shape}")
        if not (np.isfinite(arr).all() and np.isfinite(sc).all()):
            raise ValueError(f"{source}: boxes and scores must be finite")
        return PromptBoxes(arr, names, sc)

    def __len__(self) -> int:
        return len(self.classes)

    def above(self, threshold: float) -> PromptBoxes:
        """The boxes with ``score >= threshold``, in descending score order (stable)."""
        order = np.argsort(-self.scores, kind="stable")
        order = order[self.scores[order] >= threshold]
        return PromptBoxes(
            self.boxes[order], tuple(self.classes[i] for i in order), self.scores[order]
        )


@dataclass(frozen=True)
class PromptOutcome:
    """How one prompt was answered.

    Attributes:
        sample_id: The sample (prompt) id.
        tags: Its prompt type tags.
        num_referents: Referred boxes (:attr:`outside_referents` included).
        num_predicted: Predicted boxes at or above the operating threshold.
        true_positives: Of those, matched one-to-one to a referent.
        hit_25, hit_50: Top-box hit in ``[0, 1]`` at 3D IoU > 0.25 / 0.5 (a fraction only when the
            top score is tied, see the module doc); None without referents.
        referent_classes: The referents' classes (sorted, each once).
        outside_referents: Of ``num_referents``, referents of classes outside the model's set
            (:mod:`model.evaluation.outside_classes`): never matched, so recall and F1 count
            them as missed.
    """

    sample_id: str
    tags: frozenset[str]
    num_referents: int
    num_predicted: int
    true_positives: int
    hit_25: float | None
    hit_50: float | None
    referent_classes: tuple[str, ...] = ()
    outside_referents: int = 0

    @property
    def precision(self) -> float:
        return self.true_positives / self.num_predicted if self.num_predicted else 0.0

    @property
    def recall(self) -> float:
        return self.true_positives / self.num_referents if self.num_referents else 0.0

    @property
    def f1(self) -> float:
        """``2 TP / (P + R)``; 1 when nothing is referred and nothing predicted."""
        total = self.num_predicted + self.num_referents
        return 2.0 * self.true_positives / total if total else 1.0

    @property
    def exact(self) -> bool:
        """Every referent matched and no extra box."""
        return self.true_positives == self.num_predicted == self.num_referents

    @property
    def is_attribute(self) -> bool:
        """The prompt has a tag besides ``class``."""
        return bool(self.tags - {CLASS_TAG})

    def groups(self) -> tuple[str, ...]:
        """The groups of :data:`GROUPS` before :data:`CLASS_GROUPS` this prompt belongs to
        (:meth:`class_group`: the last)."""
        out = ["attribute" if self.is_attribute else "class_only"]
        if self.num_referents == 1:
            out.append("single")
        elif self.num_referents > 1:
            out.append("multiple")
        else:
            out.append("empty")
        return tuple(out)

    def class_group(self) -> str | None:
        """The :data:`CLASS_GROUPS` group of this prompt's referents (None: in neither)."""
        three = [c in VOD for c in self.referent_classes]
        if three and all(three):
            return "vod_classes"
        if three and not any(three):
            return "beyond_vod"
        return None


def match_count(predicted: PromptBoxes, referents: PromptBoxes) -> int:
    """One-to-one greedy matches of ``predicted`` (taken in descending score order) to
    ``referents``: each box takes the free referent of its class with the largest 3D IoU strictly
    above the class's official minimum overlap. Returns the number of matches."""
    if len(predicted) == 0 or len(referents) == 0:
        return 0
    order = np.argsort(-predicted.scores, kind="stable")
    ious = iou3d(predicted.boxes, referents.boxes)  # (P, R)
    free = np.ones(len(referents), dtype=bool)
    ref_cls = np.array(referents.classes, dtype=object)
    matches = 0
    for i in order:
        cls = predicted.classes[i]
        ok = free & (ref_cls == cls) & (ious[i] > _min_overlap(cls, "prediction"))
        if ok.any():
            free[int(np.argmax(np.where(ok, ious[i], -1.0)))] = False
            matches += 1
    return matches


def top_box_hits(
    predicted: PromptBoxes, referents: PromptBoxes, thresholds: Sequence[float] = ACC_IOUS
) -> tuple[float, ...]:
    """Top-box hit per IoU threshold, in ``[0, 1]`` (ties at the top score: the expected hit of a
    random pick among them); 0 without predictions. ``referents`` must not be empty."""
    if len(referents) == 0:
        raise ValueError("top_box_hits: a prompt without referents has no top-box accuracy")
    if len(predicted) == 0:
        return tuple(0.0 for _ in thresholds)
    tied = np.flatnonzero(predicted.scores == predicted.scores.max())
    ious = iou3d(predicted.boxes[tied], referents.boxes)  # (T, R)
    same = np.array(
        [[p == r for r in referents.classes] for p in (predicted.classes[i] for i in tied)]
    )
    best = np.where(same, ious, 0.0).max(axis=1)  # (T,)
    return tuple(float(np.mean(best > thr)) for thr in thresholds)


def prompt_outcome(
    sample_id: str,
    tags: Iterable[str],
    predicted: PromptBoxes,
    referents: PromptBoxes,
    threshold: float,
    outside: int = 0,
) -> PromptOutcome:
    """Score one prompt's answer: top-box hits over all of ``predicted``, set matching over the
    boxes with ``score >= threshold`` (the operating threshold). ``outside``: referents of the
    prompt beyond ``referents``, of classes outside the model's set: they count in ``R``, never
    matched (a prompt with only such referents has top-box hits of 0)."""
    if outside < 0:
        raise ValueError(f"prompt {sample_id}: outside referents must be >= 0, got {outside}")
    kept = predicted.above(threshold)
    hits: tuple[float | None, ...] = (None, None)
    if len(referents):
        hits = top_box_hits(predicted, referents, ACC_IOUS)
    elif outside:
        hits = (0.0, 0.0)
    return PromptOutcome(
        sample_id=sample_id,
        tags=frozenset(tags),
        num_referents=len(referents) + outside,
        num_predicted=len(kept),
        true_positives=match_count(kept, referents),
        hit_25=hits[0],
        hit_50=hits[1],
        referent_classes=tuple(sorted(set(referents.classes))),
        outside_referents=outside,
    )


def _pct(num: float, den: float) -> float:
    return 100.0 * num / den if den else 0.0


@dataclass(frozen=True)
class GroundingSummary(SummaryFigures):
    """Grounding figures over a set of prompts, in percent (see the module doc).

    Attributes:
        prompts: Prompts in the set.
        acc_25, acc_50: Top-box accuracy at 3D IoU > 0.25 / 0.5.
        precision, recall, f1: Set metrics micro-averaged over boxes.
        set_f1: Mean per-prompt F1 ("set F1").
        exact: Prompts answered with exactly their referent set.
        acc_prompts: Of the prompts, with at least one referent (the denominator of Acc).
        referents, predicted, true_positives: Box totals behind the micro averages.
    """

    acc_prompts: int
    referents: int
    predicted: int
    true_positives: int

    def to_dict(self) -> dict[str, float | int]:
        """Every field by name, in the order files have always had (``acc_prompts`` second)."""
        out: dict[str, float | int] = dict(self.__dict__)
        return {"prompts": out.pop("prompts"), "acc_prompts": out.pop("acc_prompts"), **out}


def summarize(outcomes: Sequence[PromptOutcome]) -> GroundingSummary:
    """Aggregate prompt outcomes (an empty set gives zeros)."""
    with_refs = [o for o in outcomes if o.hit_25 is not None and o.hit_50 is not None]
    tp = sum(o.true_positives for o in outcomes)
    pred = sum(o.num_predicted for o in outcomes)
    refs = sum(o.num_referents for o in outcomes)
    return GroundingSummary(
        prompts=len(outcomes),
        acc_prompts=len(with_refs),
        acc_25=_pct(sum(o.hit_25 for o in with_refs), len(with_refs)),  # type: ignore[misc]
        acc_50=_pct(sum(o.hit_50 for o in with_refs), len(with_refs)),  # type: ignore[misc]
        precision=_pct(tp, pred),
        recall=_pct(tp, refs),
        f1=_pct(2 * tp, pred + refs),
        set_f1=_pct(sum(o.f1 for o in outcomes), len(outcomes)),
        exact=_pct(sum(o.exact for o in outcomes), len(outcomes)),
        referents=refs,
        predicted=pred,
        true_positives=tp,
    )


@dataclass(frozen=True)
class GroundingMetrics:
    """Grounding figures of one answer set (a model or a baseline) over a split.

    Attributes:
        threshold: The operating threshold of the set metrics.
        overall: All prompts.
        by_type: Tag of :data:`GROUNDING_TYPES` -> its prompts (tags without prompts left out).
        by_group: Group of :data:`GROUPS` -> its prompts (empty groups left out).
    """

    threshold: float
    overall: GroundingSummary
    by_type: Mapping[str, GroundingSummary]
    by_group: Mapping[str, GroundingSummary]

    def to_dict(self) -> dict:
        """JSON-ready, :mod:`model.evaluation.report_file`'s keys."""
        return {
            THRESHOLD: self.threshold,
            OVERALL: self.overall.to_dict(),
            BY_TYPE: {k: v.to_dict() for k, v in self.by_type.items()},
            BY_GROUP: {k: v.to_dict() for k, v in self.by_group.items()},
        }


def grounding_metrics(outcomes: Sequence[PromptOutcome], threshold: float) -> GroundingMetrics:
    """Summaries overall, per type tag and per group of :func:`prompt_outcome` results."""
    by_type = {t: [o for o in outcomes if t in o.tags] for t in GROUNDING_TYPES}
    beyond = any(c not in VOD for o in outcomes for c in o.referent_classes)
    names = GROUPS if beyond else tuple(g for g in GROUPS if g not in CLASS_GROUPS)
    by_group = {g: [o for o in outcomes if g in (*o.groups(), o.class_group())] for g in names}
    return GroundingMetrics(
        threshold=float(threshold),
        overall=summarize(outcomes),
        by_type={k: summarize(v) for k, v in by_type.items() if v},
        by_group={k: summarize(v) for k, v in by_group.items() if v},
    )


SPLIT_NAMES: tuple[str, ...] = (*GROUPS, *GROUNDING_TYPES)
"""Column order of the split table: the groups, then the type tags."""


def format_grounding_tables(rows: Mapping[str, tuple[GroundingMetrics, float | None]]) -> str:
    """Plain-text tables of answer sets side by side.

    Args:
        rows: Row name (``model``, ``class noun``, ``oracle``) -> (metrics, entire-area 3D mAP at
            11 points, or None where not computed).

    Returns:
        The overall table (Acc, set P / R / F1, exact-set, mAP), then Acc@0.25 / set F1 / exact per
        group and per type tag, one column per answer set.
    """
    if not rows:
        return ""
    thresholds = sorted({m.threshold for m, _ in rows.values()})
    lines = [
        f"Grounding per prompt (percent; operating threshold {', '.join(f'{t:g}' for t in thresholds)}"
        "; P / R / F1 micro over boxes; set F1 = mean per-prompt F1)",
        f"{'':<12}{'prompts':>8}{'Acc@.25':>9}{'Acc@.5':>8}{'P':>7}{'R':>7}{'F1':>7}"
        f"{'set F1':>8}{'exact':>7}{'mAP 3D':>8}",
    ]
    for name, (m, map3d) in rows.items():
        o = m.overall
        shown = "-" if map3d is None else f"{map3d:.2f}"
        lines.append(
            f"{name:<12}{o.prompts:>8}{o.acc_25:>9.1f}{o.acc_50:>8.1f}{o.precision:>7.1f}"
            f"{o.recall:>7.1f}{o.f1:>7.1f}{o.set_f1:>8.1f}{o.exact:>7.1f}{shown:>8}"
        )
    lines.append("Grounding by prompt group and type (Acc@0.25 / set F1 / exact)")
    lines.append(f"{'':<12}{'prompts':>8}" + "".join(f"{name:>24}" for name in rows))
    for split in SPLIT_NAMES:
        summaries = [m.by_group.get(split) or m.by_type.get(split) for m, _ in rows.values()]
        if split in CLASS_GROUPS and all(s is None for s in summaries):
            continue
        count = max((s.prompts for s in summaries if s is not None), default=0)
        cells = [
            "-" if s is None else f"{s.acc_25:.1f} / {s.set_f1:.1f} / {s.exact:.1f}"
            for s in summaries
        ]
        lines.append(f"{split:<12}{count:>8}" + "".join(f"{c:>24}" for c in cells))
    return "\n".join(lines) + "\n"
