"""The "Query" tab's widgets: prompt box, Run, sensors, score threshold, heatmap and ground-truth
controls, the answer summary and the prompt history (:class:`QueryPanel`, :class:`PromptField`,
:class:`PromptHistory`; the answer drawn into them: :mod:`app.query.answer`).

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

Text policy: the panel hands the box's text as it is to
:meth:`app.session.ClientSession.run_prompt`, the one door of the Query tab's text, which reads it
once (:func:`app.query.prompt.read_prompt`: Enter's line breaks made spaces, then the text policy)
and runs the :class:`~app.query.prompt.Prompt` it accepts as it is from there on.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass

import numpy as np
import viser

from app.engine import MODALITY_LABELS, Modality
from app.query.heatmap_view import HeatmapView
from app.query.prompt import entered
from app.view.boxes_view import GroundTruthView
from scenes.frame import Sample

CANDIDATE_SOURCES = {"Detector proposals": "detector", "Labelled boxes": "labels"}
"""GUI label -> what the referent stage chooses among (the "Candidates" control)."""

HISTORY_SIZE = 20
"""Prompts kept in a browser's history."""

NO_HISTORY = "(no prompts yet)"
"""The history dropdown's only option before the first answer."""


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
