"""The answer on screen: its boxes and heatmap in the 3D view, the prompts run, and the summary
above its table of boxes (:class:`AnswerView`, one per browser; :func:`results_markdown`).

The summary says the answer in words (:func:`app.query.answer_words.answer_sentence`), how the
sentence was read when it is not the sentence as typed (:func:`reading_lines`), the latency
breakdown and the best boxes with their score and the frame's labelled object each overlaps
(:func:`answer_labels`, :class:`app.serving.ground_truth.Overlap`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np
import viser

from app.engine import Answer, Predictions
from app.query.answer_words import answer_sentence
from app.query.heatmap_view import HeatmapView
from app.query.panel import PromptHistory, QueryPanel, modality_label
from app.query.request import QueryRequest
from app.serving.ground_truth import FrameObjects, Overlap
from app.text import md_text
from app.view.boxes_view import PRED_STYLE, BoxesView, box_label
from scenes.geometry.classes import VOD, ClassSet

RESULT_ROWS = 10
"""Boxes listed in the answer summary."""

OVERLAP_COLUMN = "labelled object it overlaps"
"""The answer table's column naming, per box, the frame's labelled object it overlaps most
(absent on a frame without labelled objects)."""


def answer_labels(
    pred: Predictions, objects: FrameObjects
) -> tuple[tuple[Overlap | None, ...] | None, list[str]]:
    """``(overlaps, labels)`` of an answer's boxes: the labelled object of the frame each one
    overlaps most (:meth:`app.serving.ground_truth.FrameObjects.overlaps`; None for the whole answer on
    a frame without labelled objects) and its 3D label (class, score, IoU with that object)."""
    found = objects.overlaps(pred.boxes)
    labels = [
        box_label(cls, float(score), o.iou if o is not None else (None if objects.empty else 0.0))
        for cls, score, o in zip(pred.classes, pred.scores, found, strict=True)
    ]
    return (None if objects.empty else found), labels


def results_markdown(
    answer: Answer,
    overlaps: Sequence[Overlap | None] | None,
    latency_ms: float,
    known: ClassSet = VOD,
) -> str:
    """The answer summary: the answer in words (:func:`app.query.answer_words.answer_sentence`), the
    latency breakdown and the best boxes with score and the labelled object each overlaps.

    Args:
        answer: The model's answer.
        overlaps: Per box, the labelled object of the frame it overlaps most (None: none) from
            :func:`answer_labels`; None when the frame has no labelled objects (the table then
            has no such column).
        latency_ms: From the prompt's arrival at the server to the drawn answer.
        known: The served model's class set (the empty answer's words).
    """
    pred = answer.predictions
    scores = np.asarray(pred.scores).reshape(-1)
    encode = "cached" if answer.cached else f"{answer.encode_ms:.0f} ms"
    lines = [
        md_text(answer_sentence(answer.prompt, tuple(pred.classes), known)),
        "",
        f"**{len(scores)} box{'es' if len(scores) != 1 else ''}** in **{latency_ms:.0f} ms** "
        f"(ground {answer.ground_ms:.0f} ms, scene encoding {encode}"
        + (f", queued {answer.waited_ms:.0f} ms" if answer.waited_ms >= 5 else "")
        + f"; {modality_label(answer.modality)}, threshold {answer.score_threshold:.2f})",
    ]
    if getattr(pred, "truncated", False):
        lines.append("*The prompt was truncated to the text encoder's token limit.*")
    for line in reading_lines(pred, len(scores)):
        lines += ["", line]  # a paragraph each
    if len(scores):
        if overlaps is None:
            lines += ["", "| # | class | score |", "|---|---|---|"]
        else:
            lines += ["", f"| # | class | score | {OVERLAP_COLUMN} |", "|---|---|---|---|"]
        for i in range(min(len(scores), RESULT_ROWS)):
            row = f"| {i} | {md_text(pred.classes[i])} | {scores[i]:.2f} |"
            if overlaps is not None:
                found = overlaps[i]
                row += f" {md_text(found.text()) if found is not None else 'none'} |"
            lines.append(row)
        if len(scores) > RESULT_ROWS:
            lines.append(f"\n... and {len(scores) - RESULT_ROWS} more")
    return "\n".join(lines)


def reading_lines(pred: object, boxes: int) -> list[str]:
    """What the app says of how the sentence was read (``Predictions.reading``,
    :mod:`scenes.language.reading`): what was grounded when it is not the sentence as typed, one
    box for one object, and the answer's note ("No bus here ...")."""
    reading = getattr(pred, "reading", None)
    out: list[str] = []
    if reading is not None and reading.rewritten(getattr(pred, "prompt", "")):
        shown = " / ".join(f"“{md_text(t)}”" for t in reading.texts[:4])
        more = f" (and {len(reading.texts) - 4} more)" if len(reading.texts) > 4 else ""
        out.append(f"*Read as* {shown}{more}")
    if reading is not None and reading.single and boxes == 1:
        kind = "A command means one object" if reading.command else "One object is meant"
        out.append(f"*{kind}: the best box is the answer.*")
    note = getattr(pred, "note", "")
    if note:
        out.append(f"**{md_text(note)}**")
    return out


class AnswerView:
    """One browser's answer on screen: the boxes (``/pred``), the heatmap (``/heatmap``), the
    prompts run (:class:`~app.query.panel.PromptHistory`) and the Query tab's summary. Its owner
    (:class:`app.session.ClientSession`) calls it holding the browser's drawing lock.

    Args:
        scene: The browser's scene (``client.scene``).
        classes: The served model's class set (colours, the empty answer's words).
    """

    def __init__(self, scene: viser.SceneApi, classes: ClassSet) -> None:
        self.classes = classes
        self.boxes = BoxesView(scene, "/pred", PRED_STYLE)
        self.heatmap = HeatmapView(scene, "/heatmap", classes.names)
        self.history = PromptHistory()

    def clear(self) -> None:
        """Remove the boxes and the heatmap."""
        self.boxes.clear()
        self.heatmap.clear()

    def draw(
        self,
        client: viser.ClientHandle,
        panel: QueryPanel,
        answer: Answer,
        request: QueryRequest,
        objects: FrameObjects,
        drawn: Callable[[], None],
    ) -> float:
        """Draw ``answer`` to ``request``: boxes (labelled with the object of ``objects`` each
        overlaps) and heatmap at once, then ``drawn()`` (the owner's: the camera image), then the
        history and the summary. Returns the latency (ms, from the prompt's arrival)."""
        pred = answer.predictions
        overlaps, labels = answer_labels(pred, objects)
        with client.atomic():
            self.boxes.show(pred.boxes, pred.classes, labels)
            self.heatmap.visible = panel.show_heatmap.value
            self.heatmap.show(pred.heatmaps, pred.grid, request.frame.ground_z, panel.opacity.value)
        drawn()
        self.history.add(request.prompt)
        panel.history.options = self.history.options()
        panel.history.value = self.history.items[0]
        panel.rerun.disabled = False
        latency = (time.perf_counter() - request.received) * 1000.0
        panel.results.content = results_markdown(answer, overlaps, latency, self.classes)
        return latency


__all__ = [
    "OVERLAP_COLUMN",
    "RESULT_ROWS",
    "AnswerView",
    "answer_labels",
    "reading_lines",
    "results_markdown",
]
