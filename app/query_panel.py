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

**The prompt box belongs to the person typing in it** (:class:`PromptField`). Several browsers
share the frame, and viser writes a server-side value into the browser's field at once, even
while the person types (the keys that follow land after the written text: "...20 km/h.ped
prompt number 0"). So the server writes the box only in reply to this browser's own actions:
Enter (the line break removed), *History*, *Re-run*, *Use the frame's prompt*, and a frame
change this browser asked for (*Previous*, *Next*, *Frame #*) when the box still holds what the
server last wrote (the person has not typed since). A frame change made by another browser
never touches the box: the new frame's own prompt is shown under the frame number and offered by
*Use the frame's prompt*.

Text policy: a prompt runs only once :func:`scenes.utils.text_policy.clean_text` accepts it (control
and line-separator characters refused with a message naming them, at most 500 characters); the
session applies it once, in :meth:`app.session.ClientSession.run_prompt` (the one path from every
control of this tab to the model: :func:`prompt_to_run`), after :func:`one_line` has turned Enter's
line breaks into spaces; the model only checks that what it gets is not empty.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass

import numpy as np
import viser

from app.answer_words import answer_sentence
from app.boxes_view import GroundTruthView, box_label
from app.engine import MODALITY_LABELS, Answer, Modality, Predictions
from app.ground_truth import FrameObjects, Overlap
from app.heatmap_view import HeatmapView
from app.navigation import Frame
from app.text import md_text
from scenes.frame import Sample
from scenes.geometry.classes import VOD, ClassSet
from scenes.utils.text_policy import PROMPT, TextPolicyError, clean_text, collapse_spaces

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

OVERLAP_COLUMN = "labelled object it overlaps"
"""The answer table's column naming, per box, the frame's labelled object it overlaps most
(absent on a frame without labelled objects)."""


@dataclass(frozen=True)
class QueryRequest:
    """One prompt to answer.

    Attributes:
        prompt: Normalised, non-empty prompt.
        modality: Sensors to use.
        score_threshold: Operating threshold: the referent-probability cut-off on the referent
            path, the decoder's score threshold on the paper's path.
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

    def candidates(self, labelled_boxes: Callable[[Sample], object | None] | None) -> object:
        """What the referent stage chooses among: the frame's labelled boxes (from
        ``labelled_boxes``, :attr:`app.session.SessionOptions.labelled_boxes`) when the request
        asks for them, else None (the detector's proposals).

        Raises:
            ValueError: the request asks for labelled boxes the frame does not have.
        """
        if not self.labelled or labelled_boxes is None:
            return None
        boxes = labelled_boxes(self.frame.sample)
        if boxes is None:
            raise ValueError(
                f"frame {self.frame.sample.sample_id} has no labelled boxes: choose "
                "Candidates: Detector proposals"
            )
        return boxes


def prompt_to_run(prompt: str | None) -> tuple[str, tuple[str, str] | None]:
    """The prompt a box's text runs as (the text policy's form of :func:`one_line`), and the
    ``(title, body)`` of the notification that says why it cannot run (refused by the policy,
    or empty), else None."""
    try:
        text = clean_text(one_line(prompt or ""), PROMPT)
    except TextPolicyError as exc:
        return "", ("Prompt not run", exc.sentence)
    if not text:
        example = f'Type a sentence describing the objects to find, e.g. "{EXAMPLE_PROMPT}".'
        return "", ("Empty prompt", example)
    return text, None


def entered(value: str) -> bool:
    """Whether the prompt box's value holds a line break: Enter was pressed (or a line pasted)."""
    return "\n" in value or "\r" in value


def submitted_prompt(value: str) -> str | None:
    """The prompt to run when the prompt box's value holds a line break (Enter), else None.

    The line breaks become spaces and runs of spaces collapse (:func:`one_line`,
    :func:`scenes.utils.text_policy.collapse_spaces`): ``"the car\\n"`` gives ``"the car"``; ``"\\n"``
    gives ``""`` (an empty prompt, reported to the user). Other control characters are left for
    the text policy to refuse by name.
    """
    if not entered(value):
        return None
    return collapse_spaces(one_line(value))


def one_line(value: str) -> str:
    """``value`` with each line break of a multi-line field (``\\r\\n``, ``\\n``, ``\\r``: Enter
    or a pasted line) made a space; the text policy refuses every other line separator."""
    return value.replace("\r\n", " ").replace("\n", " ").replace("\r", " ")


class PromptField:
    """One browser's prompt box and what the server last wrote into it (see the module
    docstring: the box belongs to the person typing in it).

    Methods are called holding the session's lock; the browser's own updates change the
    handle's value on viser's event loop at any time, which :attr:`edited` reads.

    Args:
        handle: The prompt box.
    """

    def __init__(self, handle: viser.GuiTextHandle) -> None:
        self.handle = handle
        self._written = handle.value

    @property
    def value(self) -> str:
        return self.handle.value

    @property
    def edited(self) -> bool:
        """Whether the browser changed the box since the server last wrote it."""
        return self.handle.value != self._written

    def write(self, text: str) -> None:
        """Write ``text`` into the box (only in reply to this browser's own action)."""
        self.handle.value = text
        self._written = self.handle.value

    def offer(self, text: str, own_move: bool) -> bool:
        """A new frame's prompt: written when this browser asked for the frame and the box is
        not :attr:`edited`; else left to *Use the frame's prompt*. Returns whether it was."""
        if not own_move or self.edited:
            return False
        self.write(text)
        return True


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


def answer_labels(
    pred: Predictions, objects: FrameObjects
) -> tuple[tuple[Overlap | None, ...] | None, list[str]]:
    """``(overlaps, labels)`` of an answer's boxes: the labelled object of the frame each one
    overlaps most (:meth:`app.ground_truth.FrameObjects.overlaps`; None for the whole answer on
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
    """The answer summary: the answer in words (:func:`app.answer_words.answer_sentence`), the
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


@dataclass(frozen=True)
class QueryPanel:
    """Handles of the "Query" tab (built by :func:`build_query_panel`)."""

    prompt: viser.GuiTextHandle
    run: viser.GuiButtonHandle
    use_frame_prompt: viser.GuiButtonHandle
    modality: viser.GuiDropdownHandle
    threshold: viser.GuiSliderHandle
    show_heatmap: viser.GuiCheckboxHandle
    opacity: viser.GuiSliderHandle
    show_gt: viser.GuiCheckboxHandle
    show_others: viser.GuiCheckboxHandle
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

    def wire_prompts(
        self,
        run: Callable[..., object],
        write: Callable[[str], None],
        sample: Callable[[], Sample | None],
        rerun_last: Callable[[], None],
    ) -> None:
        """Enter in the prompt box, *Run* and *Re-run* call ``run(prompt, write=...)``
        (:meth:`app.session.ClientSession.run_prompt`); *Use the frame's prompt* and *History*
        ``write(prompt)``; a changed *Sensors*, *Score threshold* or *Candidates*
        ``rerun_last()``; ``sample()`` is the sample on screen."""

        @self.prompt.on_update
        def _(event: viser.GuiEvent) -> None:
            if event.client is not None and entered(self.prompt.value):
                # The box is rewritten without the line break (fires this without client).
                run(self.prompt.value, write=True)

        @self.run.on_click
        def _(_: viser.GuiEvent) -> None:
            run(self.prompt.value)

        @self.use_frame_prompt.on_click
        def _(_: viser.GuiEvent) -> None:
            shown = sample()
            if shown is not None and shown.prompt:
                write(shown.prompt)

        @self.rerun.on_click
        def _(_: viser.GuiEvent) -> None:
            if self.history.value != NO_HISTORY:
                run(self.history.value, write=True)

        @self.history.on_update
        def _(event: viser.GuiEvent) -> None:
            if event.client is not None and self.history.value != NO_HISTORY:
                write(self.history.value)

        def changed(event: viser.GuiEvent) -> None:
            if event.client is not None:
                rerun_last()

        for handle in (self.modality, self.threshold, self.candidates):
            if handle is not None:
                handle.on_update(changed)

    def wire_layers(
        self,
        lock: AbstractContextManager,
        heatmap: HeatmapView,
        gt: GroundTruthView,
        show_gt_in_camera: Callable[[bool, bool], None],
    ) -> None:
        """*Heatmap*, *Heatmap opacity*, *Ground truth* and *Other annotations* show or hide the
        layers (drawing holding ``lock``, the browser's lock); ``show_gt_in_camera(ground_truth,
        others)`` for the camera panel."""

        @self.opacity.on_update
        def _(_: viser.GuiEvent) -> None:
            with lock:
                heatmap.set_opacity(self.opacity.value)

        @self.show_heatmap.on_update
        def _(_: viser.GuiEvent) -> None:
            with lock:
                heatmap.visible = self.show_heatmap.value

        def ground_truth(_: viser.GuiEvent) -> None:
            with lock:
                gt.visible = self.show_gt.value
                gt.others_visible = self.show_others.value
            show_gt_in_camera(self.show_gt.value, self.show_others.value)

        self.show_gt.on_update(ground_truth)
        self.show_others.on_update(ground_truth)


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
    use_frame_prompt = gui.add_button(
        "Use the frame's prompt",
        icon=viser.Icon.ARROW_BACK_UP,
        disabled=not prompt,
        hint="Puts the frame's own prompt (shown under Frame #) into the box",
    )
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
    show_heatmap = gui.add_checkbox(
        "Heatmap",
        True,
        hint="Where the model finds the prompt's objects, on the ground (the referent "
        "probabilities; on the paper's path the C3D-RECHead heatmap)",
    )
    opacity = gui.add_slider("Heatmap opacity", 0.0, 1.0, 0.05, heatmap_opacity)
    show_gt = gui.add_checkbox(
        "Ground truth",
        True,
        hint="Every labelled object of the frame in its class colour, numbered from the nearest; "
        "the referents of the frame's own prompt (or of the command in play) thick and green",
    )
    show_others = gui.add_checkbox(
        "Other annotations",
        True,
        hint="The labelled objects that are not the referents, as one group: in the 3D view, "
        "the camera image and the Annotate tab's ready-made boxes",
    )
    results = gui.add_markdown("*Type a prompt and press Enter.*")
    history = gui.add_dropdown("History", (NO_HISTORY,), initial_value=NO_HISTORY)
    rerun = gui.add_button("Re-run", icon=viser.Icon.REFRESH, disabled=True)
    return QueryPanel(
        prompt=prompt_box,
        run=run,
        use_frame_prompt=use_frame_prompt,
        modality=modality,
        threshold=threshold,
        show_heatmap=show_heatmap,
        opacity=opacity,
        show_gt=show_gt,
        show_others=show_others,
        results=results,
        history=history,
        rerun=rerun,
        candidates=candidates,
    )
