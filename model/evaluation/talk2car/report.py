"""The report of ``python -m model.evaluate --talk2car`` (:mod:`model.evaluation.talk2car.kind`):
table II's figures over a split's commands (:mod:`model.evaluation.talk2car.metrics`), overall and
on the rain and night subsets (:func:`subset_of`, from the nuScenes scene descriptions; fog too,
which only synthetic roots have), per referent class, and for a checkpoint of more classes than
View-of-Delft's per group (:data:`GROUPS`: the three, and the classes beyond them), Talk2Car's
AP50, and top-1 beside the class-noun and language-blind baselines."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from model.evaluation.talk2car.metrics import table_ii, talk2car_ap, top1_hits
from model.evaluation.talk2car.predict import CommandPrediction, projected_2d_box
from scenes.geometry.classes import beyond_vod

SUBSETS: tuple[str, ...] = ("all", "rain", "night", "fog")
"""The table's rows: every command, and those of scenes whose description names rain, night or
fog (table II's subsets are rain and night; nuScenes has no fog, the synthetic roots' third weather
does, and an empty subset is left out of the table)."""


GROUPS: tuple[str, ...] = ("the three", "beyond the three")
"""The class groups' rows when some referent is beyond View-of-Delft's three classes
(:func:`scenes.geometry.classes.beyond_vod`): cars, pedestrians and bicycles (cyclists), and the
seven others of nuScenes' detection classes."""


def subset_of(description: str) -> tuple[str, ...]:
    """The subsets a scene belongs to: ``all``, plus ``rain`` / ``night`` / ``fog`` when its
    description says so (a word starting with the subset's name; case-insensitive)."""
    words = description.lower().replace(",", " ").replace(".", " ").split()
    return ("all", *(s for s in SUBSETS[1:] if any(w.startswith(s) for w in words)))


@dataclass(frozen=True)
class Talk2CarReport:
    """Figures of one split (percent).

    Attributes:
        rows: subset, referent class or class group -> ``{"commands", "BEV AP_A", "3D AP_A", "BEV AP_B", "3D AP_B", "AP50 2D",
            "top-1", "top-1 class noun", "top-1 language-blind"}``.
        predictions: The predictions scored (what the predictions file holds).
    """

    rows: dict[str, dict[str, float]]
    predictions: tuple[CommandPrediction, ...] = field(default=(), repr=False, compare=False)

    def format_tables(self) -> str:
        """The printed table: one line per subset."""
        names = (
            "commands",
            "BEV AP_A",
            "3D AP_A",
            "BEV AP_B",
            "3D AP_B",
            "AP50 2D",
            "top-1",
            "top-1 class noun",
            "top-1 language-blind",
        )
        first = max(7, *(len(k) for k in self.rows))
        head = f"{'subset':<{first}}" + "".join(f"{n:>{max(len(n), 8) + 2}}" for n in names)
        lines = [head]
        for subset, row in self.rows.items():
            cells = []
            for n in names:
                width = max(len(n), 8) + 2
                value = row[n]
                cells.append(
                    f"{int(value):>{width}d}" if n == "commands" else f"{value:>{width}.2f}"
                )
            lines.append(f"{subset:<{first}}" + "".join(cells))
        return "\n".join(lines) + "\n"

    def to_dict(self) -> dict[str, dict[str, float]]:
        return {k: dict(v) for k, v in self.rows.items()}


def figures(predictions: Sequence[CommandPrediction]) -> dict[str, float]:
    """One row of the table over ``predictions``."""
    answers = [p.answer for p in predictions]
    row: dict[str, float] = {"commands": float(len(predictions))}
    row.update(table_ii(answers))
    best_2d = [
        projected_2d_box(p.answer.boxes[0], p.frame) if len(p.answer.boxes) else None
        for p in predictions
    ]
    row["AP50 2D"] = talk2car_ap(best_2d, [list(p.command.box_2d) for p in predictions])
    n = max(len(predictions), 1)
    row["top-1"] = 100.0 * float(top1_hits(answers).sum()) / n
    row["top-1 class noun"] = 100.0 * float(top1_hits([p.noun for p in predictions]).sum()) / n
    blind = [1.0 / p.in_view_same_class if p.referent_in_view else 0.0 for p in predictions]
    row["top-1 language-blind"] = 100.0 * float(np.sum(blind)) / n
    return row


def build_report(predictions: Sequence[CommandPrediction]) -> Talk2CarReport:
    """The table's rows: :data:`SUBSETS` (an empty subset is left out), then one per referent
    class (most commands first), then :data:`GROUPS` when some referent is beyond the three."""
    rows = {}
    for subset in SUBSETS:
        chosen = [p for p in predictions if subset in subset_of(p.description)]
        if chosen or subset == "all":
            rows[subset] = figures(chosen)
    by_class: dict[str, list[CommandPrediction]] = {}
    for p in predictions:
        by_class.setdefault(p.answer.referent_class, []).append(p)
    for name, chosen in sorted(by_class.items(), key=lambda kv: (-len(kv[1]), kv[0])):
        rows[name] = figures(chosen)
    beyond = [p for p in predictions if beyond_vod(p.answer.referent_class)]
    if beyond:
        three = [p for p in predictions if not beyond_vod(p.answer.referent_class)]
        for name, chosen in zip(GROUPS, (three, beyond), strict=True):
            if chosen:
                rows[name] = figures(chosen)
    return Talk2CarReport(rows, tuple(predictions))


__all__ = ["GROUPS", "SUBSETS", "Talk2CarReport", "build_report", "figures", "subset_of"]
