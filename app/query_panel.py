"""The "Query" tab: prompt box, Run, sensors, score threshold, heatmap and ground-truth controls,
the answer summary and the prompt history.

**Enter runs the prompt.** The prompt box is a multi-line text area, and a line break in its
value means Enter was pressed: the session strips it and runs the prompt (Shift+Enter and pasted
multi-line text run it too). Why not viser's ``add_form`` (whose ``on_submit`` fires on Enter in a
single-line input)? In viser 1.1.1 the form's submit message and the input's value updates share
one 50 ms throttled sender that keeps only the *latest* pending message, so an Enter pressed
within 50 ms of the last keystroke replaces that keystroke's value update and the server would run
a stale prompt. A line break travels inside the value update itself, so the server always sees
the text the browser shows.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import viser

from app.engine import MODALITY_LABELS, Answer, Modality
from app.navigation import Frame
from app.text import md_text

CANDIDATE_SOURCES = {"Detector proposals": "detector", "Labelled boxes": "labels"}
"""GUI label -> what the referent stage chooses among (the "Candidates" control)."""

HISTORY_SIZE = 20
"""Prompts kept in a browser's history."""

NO_HISTORY = "(no prompts yet)"
"""The history dropdown's only option before the first answer."""

RESULT_ROWS = 10
"""Boxes listed in the answer summary."""

EXAMPLE_PROMPT = "the car about 15 metres ahead"
"""Suggested in the empty-prompt notification."""


@dataclass(frozen=True)
class QueryRequest:
    """One prompt to answer.

    Attributes:
        prompt: Normalised, non-empty prompt.
        modality: Sensors to use.
        score_threshold: Decoder threshold.
        frame: The frame on screen when the prompt was sent.
        generation: The session's generation number at that moment.
        received: ``time.perf_counter()`` when the server received the prompt.
        labelled: Choose among the frame's labelled boxes instead of the detector's proposals.
    """

    prompt: str
    modality: Modality
    score_threshold: float
    frame: Frame
    generation: int
    received: float
    labelled: bool = False


def submitted_prompt(value: str) -> str | None:
    """The prompt to run when the prompt box's value holds a line break (Enter), else None.

    The line breaks become spaces and runs of whitespace collapse: ``"the car\\n"`` gives
    ``"the car"``; ``"\\n"`` gives ``""`` (an empty prompt, reported to the user).
    """
    if "\n" not in value and "\r" not in value:
        return None
    return normalise_prompt(value)


def normalise_prompt(text: str) -> str:
    """``text`` with surrounding whitespace stripped and inner whitespace collapsed to spaces."""
    return " ".join(text.split())


class PromptHistory:
    """The prompts a browser ran, most recent first, without duplicates, at most ``size``."""

    def __init__(self, size: int = HISTORY_SIZE) -> None:
        self.size = size
        self.items: list[str] = []

    def add(self, prompt: str) -> None:
        """Put ``prompt`` first (moving it up when already present)."""
        if prompt in self.items:
            self.items.remove(prompt)
        self.items.insert(0, prompt)
        del self.items[self.size :]

    def options(self) -> tuple[str, ...]:
        """Dropdown options (:data:`NO_HISTORY` when empty)."""
        return tuple(self.items) if self.items else (NO_HISTORY,)


def modality_label(modality: Modality) -> str:
    """GUI label of a modality."""
    return next(label for label, value in MODALITY_LABELS.items() if value == modality)


def results_markdown(answer: Answer, ious: np.ndarray, latency_ms: float) -> str:
    """The answer summary: latency breakdown and the best boxes with score and IoU.

    Args:
        answer: The model's answer.
        ious: ``(K,)`` best 3D IoU of each box with the ground truth (NaN without ground truth).
        latency_ms: From the prompt's arrival at the server to the drawn answer.
    """
    pred = answer.predictions
    scores = np.asarray(pred.scores).reshape(-1)
    encode = "cached" if answer.cached else f"{answer.encode_ms:.0f} ms"
    lines = [
        f"**{len(scores)} box{'es' if len(scores) != 1 else ''}** in **{latency_ms:.0f} ms** "
        f"(ground {answer.ground_ms:.0f} ms, scene encoding {encode}"
        + (f", queued {answer.waited_ms:.0f} ms" if answer.waited_ms >= 5 else "")
        + f"; {modality_label(answer.modality)}, threshold {answer.score_threshold:.2f})",
    ]
    if getattr(pred, "truncated", False):
        lines.append("*The prompt was truncated to the text encoder's token limit.*")
    if len(scores):
        lines += ["", "| # | class | score | IoU w/ GT |", "|---|---|---|---|"]
        for i in range(min(len(scores), RESULT_ROWS)):
            iou = f"{ious[i]:.2f}" if np.isfinite(ious[i]) else "-"
            lines.append(f"| {i} | {md_text(pred.classes[i])} | {scores[i]:.2f} | {iou} |")
        if len(scores) > RESULT_ROWS:
            lines.append(f"\n... and {len(scores) - RESULT_ROWS} more")
    return "\n".join(lines)


@dataclass(frozen=True)
class QueryPanel:
    """Handles of the "Query" tab (built by :func:`build_query_panel`)."""

    prompt: viser.GuiTextHandle
    run: viser.GuiButtonHandle
    modality: viser.GuiDropdownHandle
    threshold: viser.GuiSliderHandle
    show_heatmap: viser.GuiCheckboxHandle
    opacity: viser.GuiSliderHandle
    show_gt: viser.GuiCheckboxHandle
    results: viser.GuiMarkdownHandle
    history: viser.GuiDropdownHandle
    rerun: viser.GuiButtonHandle
    candidates: viser.GuiDropdownHandle | None = None

    def selected_modality(self) -> Modality:
        return MODALITY_LABELS.get(self.modality.value, "both")

    def labelled_selected(self) -> bool:
        """Whether the "Candidates" control asks for the frame's labelled boxes."""
        if self.candidates is None:
            return False
        return CANDIDATE_SOURCES.get(self.candidates.value, "detector") == "labels"


def build_query_panel(
    gui: viser.GuiApi,
    modalities: Sequence[Modality],
    score_threshold: float,
    heatmap_opacity: float = 0.7,
    prompt: str = "",
    labelled: bool = False,
) -> QueryPanel:
    """Add the Query widgets to ``gui`` (in the current container) and return their handles;
    ``labelled``: the frames have labelled boxes (a "Candidates" control is added)."""
    prompt_box = gui.add_text(
        "Prompt", prompt, multiline=True, hint="Describe the objects to find; Enter runs it"
    )
    run = gui.add_button("Run", color="green", icon=viser.Icon.PLAYER_PLAY)
    labels = tuple(modality_label(m) for m in modalities)
    modality = gui.add_dropdown(
        "Sensors", labels, initial_value=labels[0], hint="The other sensor's points are emptied"
    )
    candidates = None
    if labelled:
        names = tuple(CANDIDATE_SOURCES)
        candidates = gui.add_dropdown(
            "Candidates",
            names,
            initial_value=names[0],
            hint="What the answer is chosen among: the detector's proposals, or the frame's "
            "labelled boxes (grounding apart from detection)",
        )
    threshold = gui.add_slider(
        "Score threshold", 0.0, 0.95, 0.01, float(np.clip(score_threshold, 0.0, 0.95))
    )
    show_heatmap = gui.add_checkbox("Heatmap", True, hint="C3D-RECHead heatmap on the ground")
    opacity = gui.add_slider("Heatmap opacity", 0.0, 1.0, 0.05, heatmap_opacity)
    show_gt = gui.add_checkbox(
        "Ground truth", True, hint="The boxes the sample's own prompt refers to"
    )
    results = gui.add_markdown("*Type a prompt and press Enter.*")
    history = gui.add_dropdown("History", (NO_HISTORY,), initial_value=NO_HISTORY)
    rerun = gui.add_button("Re-run", icon=viser.Icon.REFRESH, disabled=True)
    return QueryPanel(
        prompt=prompt_box,
        run=run,
        modality=modality,
        threshold=threshold,
        show_heatmap=show_heatmap,
        opacity=opacity,
        show_gt=show_gt,
        results=results,
        history=history,
        rerun=rerun,
        candidates=candidates,
    )
