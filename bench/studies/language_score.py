"""How the language suite scores an answer, and its per-family table.

An answer is the boxes a model returns for a sentence (LiDAR frame ``(K, 7)``, class names and
scores, down to the model's smallest returned score); its **set** is the boxes scoring at least the
operating threshold (what the app shows). A box **matches** a referent of its class when their BEV
centres lie within :data:`scenes.geometry.classes.MATCH_DISTANCE` of each other, one to one, boxes
taken by score (:func:`scenes.geometry.boxes.match_by_centre`). Per case:

- ``empty``: the set is empty;
- ``top1``: the highest-scoring box (any score) matches a referent; no box is a miss;
- ``f1``: ``2 * matched / (|set| + |referents|)``, 1 when both are empty; ``exact``: the set matches
  the referents one to one, nothing left over on either side.

Each family's figures (:data:`FIGURES`) are means over its cases, in percent: out-of-class and
unsatisfiable: no box; ordinal and relation: top-1; negation, exclusion, counting: set F1 and
exact set; rewording: top-1 and set F1; command and its description counterpart: top-1.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from scenes.geometry.boxes import match_by_centre
from scenes.geometry.classes import ALL_CLASSES, MATCH_DISTANCE

FIGURES = {
    "out_of_class": ("empty",),
    "unsatisfiable": ("empty",),
    "negation": ("f1", "exact"),
    "exclusion": ("f1", "exact"),
    "counting": ("f1", "exact"),
    "ordinal": ("top1",),
    "relation": ("top1",),
    "rewording": ("top1", "f1"),
    "command": ("top1",),
    "command_description": ("top1",),
}
FIGURE_NAMES = {"empty": "no box %", "top1": "top-1 %", "f1": "set F1", "exact": "exact set %"}


@dataclass(frozen=True)
class Answer:
    """Boxes ``(K, 7)`` LiDAR frame, their class names and scores, any order."""

    boxes: np.ndarray
    classes: tuple[str, ...]
    scores: np.ndarray

    @staticmethod
    def of(boxes: object, classes: Sequence[str], scores: object) -> Answer:
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
        s = np.asarray(scores, dtype=np.float64).reshape(-1)
        if len(b) != len(s) or len(classes) != len(s):
            raise ValueError(f"Answer: {len(b)} boxes, {len(classes)} classes, {len(s)} scores")
        return Answer(b, tuple(classes), s)


@dataclass(frozen=True)
class Outcome:
    """One case's scores (module docstring)."""

    empty: bool
    top1: float
    f1: float
    exact: bool

    def figure(self, name: str) -> float:
        return float(getattr(self, name))


def _matches(
    answer: Answer, order: np.ndarray, targets: np.ndarray, target_cls: Sequence[str]
) -> int:
    if len(order) == 0 or len(targets) == 0:
        return 0
    labels = np.array([ALL_CLASSES.index(answer.classes[i]) for i in order])
    target_labels = np.array([ALL_CLASSES.index(c) for c in target_cls])
    limits = np.array([MATCH_DISTANCE[c] for c in ALL_CLASSES])
    index = match_by_centre(answer.boxes[order], labels, targets, target_labels, limits)
    return int((index >= 0).sum())


def score(
    answer: Answer, referents: np.ndarray, referent_classes: Sequence[str], threshold: float
) -> Outcome:
    """Score one answer against referent boxes ``(T, 7)`` (LiDAR frame) at ``threshold``."""
    targets = np.asarray(referents, dtype=np.float64).reshape(-1, 7)
    order = np.argsort(-answer.scores, kind="stable")
    kept = order[answer.scores[order] >= threshold]
    top1 = float(bool(len(order)) and _matches(answer, order[:1], targets, referent_classes) == 1)
    matched = _matches(answer, kept, targets, referent_classes)
    total = len(kept) + len(targets)
    f1 = 1.0 if total == 0 else 2.0 * matched / total
    exact = matched == len(kept) == len(targets)
    return Outcome(empty=len(kept) == 0, top1=top1, f1=f1, exact=exact)


def oracle_outcome(candidates: int, referents: int) -> Outcome:
    """The language-blind oracle's scores: it answers every one of ``candidates`` actors of the
    named class with score 1 (all referents among them); its top-1 is the chance that a random
    one of them is a referent, as a fraction."""
    f1 = 1.0 if candidates + referents == 0 else 2.0 * referents / (candidates + referents)
    top1 = referents / candidates if candidates else 0.0
    return Outcome(candidates == 0, top1, f1, candidates == referents)


def family_figures(
    outcomes: Sequence[tuple[str, Outcome]],
) -> dict[str, dict[str, float | int]]:
    """Per family: ``cases`` and each of its :data:`FIGURES` in percent (F1 x 100)."""
    out: dict[str, dict[str, float | int]] = {}
    for family, names in FIGURES.items():
        rows = [o for f, o in outcomes if f == family]
        figs: dict[str, float | int] = {"cases": len(rows)}
        for name in names:
            figs[name] = 100.0 * float(np.mean([o.figure(name) for o in rows])) if rows else 0.0
        out[family] = figs
    return out


def format_table(columns: Mapping[str, Mapping[str, Mapping[str, float | int]]]) -> str:
    """A markdown table: one row per (family, figure), one column per answerer (e.g. the model,
    the class-noun prompt, the oracle), the cases beside the family."""
    names = list(columns)
    first = next(iter(columns.values()))
    lines = [
        "| family | cases | figure | " + " | ".join(names) + " |",
        "| --- | ---: | --- | " + " | ".join("---:" for _ in names) + " |",
    ]
    for family in first:
        for fig in (k for k in first[family] if k != "cases"):
            cells = []
            for n in names:
                value = columns[n].get(family, {}).get(fig)
                cells.append("-" if value is None else f"{value:.1f}")
            lines.append(
                f"| {family.replace('_', '-')} | {first[family]['cases']} | "
                f"{FIGURE_NAMES.get(fig, fig)} | " + " | ".join(cells) + " |"
            )
    return "\n".join(lines) + "\n"
