"""Referents of classes outside the model's class set: counted, named, never a silent change of
score (issue 50 item 4).

A Talk2Radar ``label_2`` lists a prompt's referents. They are read into the model's class set
(:func:`scenes.frame.kitti.labels_to_boxes`): the three-class checkpoint reads no
``Bicycle`` of a ``--classes nuscenes`` root, and a ``Truck`` or ``Tram`` label of a three-class
root is no box of its set. :func:`scenes.frame.kitti.outside_class_counts` counts what is
left out (``DontCare`` aside), and ``python -m model.evaluate`` decides:

- **All referents outside the set** (a prompt about three bicycles for the three-class model):
  the prompt is *reported apart*. It is in none of the grounding figures (overall, per group, per
  type, the baselines' too), never in the empty-answer group (its right answer is not "no box":
  it is an answer the model cannot give), and it is counted in its own line and JSON field
  (:data:`model.evaluation.report_file.OUTSIDE`: ``prompts_apart`` and their sample ids). Its
  frame stays in the official mAP, whose prediction files are written for every frame (the
  protocol scores only the set's classes: the outside labels count for no class).
- **Some referents outside the set** (a car and a truck for the three-class model): the prompt
  is scored and the outside referents stay in it as referents the model cannot answer: they
  count in ``R`` (recall and F1 drop, the prompt is no exact set, a two-referent prompt stays
  one of the "multiple" group) and are never matched
  (:attr:`model.evaluation.grounding.PromptOutcome.outside_referents`).

One line per run names them (:meth:`OutsideClasses.note`, the last line of the evaluation's
tables), e.g. ``12 referents of classes outside the model's set (Bicycle 9, Truck 3): 4 prompts
whose referents all lie outside it reported apart, out of every grounding figure (00003, ...);
the other 3 stay in their prompts as referents the model cannot answer (missed)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from model.evaluation.report_file import (
    OUTSIDE_APART,
    OUTSIDE_APART_IDS,
    OUTSIDE_CLASS_SET,
    OUTSIDE_REFERENTS,
    OUTSIDE_SCORED,
)
from scenes.frame.kitti import outside_class_phrase

SHOWN_IDS = 5
"""Sample ids of the prompts reported apart that the line names (the JSON lists all)."""


@dataclass(frozen=True)
class OutsideClasses:
    """The referents outside the model's class set over an evaluated split.

    Attributes:
        class_set: The model's class set name (``vod``, ``nuscenes``).
        referents: Label name -> referents of that name outside the set, over every prompt.
        apart: Sample ids of the prompts whose referents all lie outside the set (reported
            apart), in evaluation order.
        apart_referents: Of the counted referents, those of the prompts reported apart.
    """

    class_set: str = "vod"
    referents: Mapping[str, int] = field(default_factory=dict)
    apart: tuple[str, ...] = ()
    apart_referents: int = 0

    @classmethod
    def of(
        cls, class_set: str, per_prompt: Mapping[str, Mapping[str, int]], apart: tuple[str, ...]
    ) -> OutsideClasses:
        """The tally of ``per_prompt`` (sample id -> its outside label names and counts) with
        the prompts reported apart, ``apart``."""
        totals: dict[str, int] = {}
        for counts in per_prompt.values():
            for name, n in counts.items():
                totals[name] = totals.get(name, 0) + n
        in_apart = sum(sum(per_prompt.get(sid, {}).values()) for sid in apart)
        return cls(class_set, dict(sorted(totals.items())), tuple(apart), in_apart)

    @property
    def total(self) -> int:
        """Referents outside the set, over every prompt."""
        return sum(self.referents.values())

    @property
    def scored(self) -> int:
        """Outside referents that stay in scored prompts as referents the model cannot answer."""
        return self.total - self.apart_referents

    def note(self) -> str | None:
        """The run's one line about them (module docstring), or None when there is none."""
        if not self.total:
            return None
        parts = []
        if self.apart:
            shown = ", ".join(self.apart[:SHOWN_IDS]) + (
                ", ..." if len(self.apart) > SHOWN_IDS else ""
            )
            prompts = f"{len(self.apart)} prompt" + ("s" if len(self.apart) > 1 else "")
            parts.append(
                f"{prompts} whose referents all lie outside it reported apart, out of every "
                f"grounding figure ({shown})"
            )
        if self.scored:
            who = f"the other {self.scored}" if self.apart else "they"
            verb = "stays" if self.apart and self.scored == 1 else "stay"
            parts.append(
                f"{who} {verb} in their prompts as referents the model cannot answer (missed)"
            )
        return f"{outside_class_phrase(self.referents)}: " + "; ".join(parts)

    def to_dict(self) -> dict:
        """JSON-ready, :mod:`model.evaluation.report_file`'s keys."""
        return {
            OUTSIDE_CLASS_SET: self.class_set,
            OUTSIDE_REFERENTS: dict(self.referents),
            OUTSIDE_SCORED: self.scored,
            OUTSIDE_APART: len(self.apart),
            OUTSIDE_APART_IDS: list(self.apart),
        }
