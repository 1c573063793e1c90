"""Sentence-first pairs on labelled frames: the referent stage pre-selects the referents.

On a frame whose objects are labelled (a View-of-Delft release served directly, or ``launch.py
--scene-labels VOD_ROOT``) and with a referent-path model (the app's
:attr:`app.session.SessionOptions.labelled_boxes`), making a pair is typing its sentence: while the
annotator types in *Pair prompt*, :class:`ReferentPicker` runs the referent stage over the
frame's labelled boxes (``encode_scene(..., candidates=LabelledBoxes)``, through the engine's
worker pool, :data:`DEBOUNCE_S` after the last keystroke: never while the person types) and puts the boxes whose referent
probability reaches the operating threshold into the draft; the others stay offered as
ready-made boxes. A click on a labelled box toggles it in or out of the pair (*A* adds the one
chosen under *Object*, Delete removes the selected one).

**Typing never waits for the model; the newest sentence wins.** A keystroke only restarts the
pause's timer (the server's keystroke callback does no model work). One pick runs at a time: a
pause that comes while a pick runs waits for it and then picks the sentence as it is by then; a
request that a newer keystroke made stale before it ran is dropped without running the model,
and a pick that a keystroke made stale while it ran changes nothing.

What the annotator decides wins: once they toggle, add, place or delete a box by hand, typing no
longer changes the boxes (*Pick referents*, key L, or *Use predictions*, U, asks the model again).
Hand-placed boxes are never removed by a pick. Enter saves only a choice made for the sentence as
it is now: when the pick is missing or older than the last keystroke, Enter picks first and
shows the result without saving (a second Enter saves), so nothing is saved unseen.
"""

from __future__ import annotations

import logging
import threading

import numpy as np

from annotate import Draft
from app.annotate_tab.labelled import Labelled
from app.annotate_tab.panel import AnnotationPanel, Part

log = logging.getLogger(__name__)

DEBOUNCE_S = 0.3
"""Seconds without a keystroke before the referents of the sentence are picked."""

PICK_TIMEOUT_S = 60.0
"""Longest wait for a pick asked for by Enter (the first pick of a frame encodes it)."""


class ReferentPicker:
    """The referent pre-selection of one browser's Annotate tab (see the module docstring).

    Args:
        panel: The tab's state and drawing.
    """

    def __init__(self, panel: AnnotationPanel) -> None:
        self.panel = panel
        panel.editor.reset_listeners.append(self.reset)
        panel.note = self.note
        panel.referents_for = lambda: self.picked_for
        self.auto = True
        """Whether typing picks the referents (False once the annotator chose by hand)."""
        self.picked_for: str | None = None
        """The sentence the draft's labelled boxes were picked for (None: no pick yet)."""
        self._generation = 0
        self._timer: threading.Timer | None = None
        self._lock = threading.Lock()
        self._running = False
        """Whether a pick of the typing runs (or is queued in the engine's pool)."""
        self._due: int | None = None
        """The generation a pause asked a pick for while one was running (None: none)."""
        self.model_runs = 0
        """Picks that ran the model (what the newest-wins rule saves is counted here)."""

    # ------------------------------------------------------------------ state

    def labelled(self) -> Labelled | None:
        """The labelled boxes of the draft's frame (None: sentence-first is off there)."""
        return self.panel.labelled()

    def note(self) -> str | None:
        """What the status line says about the referents (None: sentence-first is off)."""
        if self.labelled() is None:
            return None
        if not self.auto:
            return "Referents chosen by hand (L: let the model pick for the sentence)."
        if self.picked_for is None:
            return "Type the sentence: the referents are picked among the labelled boxes."
        return "Referents picked by the model for the sentence: click a box to toggle it."

    def reset(self, draft: Draft) -> None:
        """The editor started over (:attr:`annotate.DraftEditor.reset_listeners`): for a new
        pair typing picks again; a reopened pair keeps the boxes it was saved with."""
        with self._lock:
            self._generation += 1
            self.auto, self.picked_for = draft.sample_id is None, None
            if self._timer is not None:
                self._timer.cancel()

    def by_hand(self) -> None:
        """The annotator changed the boxes themselves: typing no longer picks."""
        with self._lock:
            self._generation += 1
            self.auto = False
            if self._timer is not None:
                self._timer.cancel()

    def prefetch(self) -> None:
        """Encode the draft's frame with its labelled boxes in the background (a new frame on
        screen), so that the first pick does not wait for it."""
        p = self.panel
        frame = p.frame
        source = p.session.options.labelled_boxes
        if frame is None or source is None or self.labelled() is None:
            return
        engine = p.session.engine
        engine.prefetch(frame.sample, engine.modalities[0], source(frame.sample))

    # ------------------------------------------------------------------ picking

    def typed(self) -> None:
        """The sentence changed: pick its referents after :data:`DEBOUNCE_S` of quiet (only
        while every box of the draft is a labelled box: the annotator placing their own boxes
        is making the pair by hand)."""
        labelled = self.labelled()
        if not self.auto or labelled is None:
            return
        if any(labelled.index_of(b.box) is None for b in self.panel.editor.draft.boxes):
            return
        with self._lock:
            self._generation += 1
            generation = self._generation
            if self._timer is not None:
                self._timer.cancel()
            self._timer = threading.Timer(DEBOUNCE_S, self._paused, (generation,))
            self._timer.daemon = True
            self._timer.start()

    def _paused(self, generation: int) -> None:
        """A pause after keystroke ``generation``: pick now, or after the pick that runs."""
        with self._lock:
            if generation != self._generation:
                return
            if self._running:
                self._due = generation
                return
            self._running = True
        self.panel.session.engine.submit(self.panel.guarded, lambda: self._picks(generation))

    def _picks(self, generation: int) -> None:
        """Pick for ``generation``, then for the pause that came meanwhile, if any (one at a
        time: the newest request wins, the older ones are dropped)."""
        while True:
            try:
                self.pick(generation)
            except BaseException:
                with self._lock:
                    self._running, self._due = False, None
                raise
            with self._lock:
                due, self._due = self._due, None
                if due is None or due != self._generation:
                    self._running = False
                    return
            generation = due

    def pick(self, generation: int | None = None) -> int | None:
        """Pick the referents of the draft's sentence now (blocking: the model's work); returns
        how many labelled boxes were picked, None when nothing was done (no sentence, no labelled
        boxes, or a newer keystroke or edit came meanwhile)."""
        p = self.panel
        with p.session.lock:
            labelled, frame = self.labelled(), p.frame
            prompt = p.editor.draft.prompt.strip()
        if labelled is None or frame is None or not prompt:
            return None
        if generation is not None and generation != self._generation:
            return None  # a newer keystroke: this request is dropped before the model runs
        self.model_runs += 1
        engine = p.session.engine
        source = p.session.options.labelled_boxes
        candidates = source(frame.sample) if source is not None else None
        answer = engine.answer(frame.sample, engine.modalities[0], prompt, 0.0, candidates)
        threshold = float(p.session.options.score_threshold)
        scores = np.asarray(answer.predictions.scores, dtype=np.float64)
        chosen = {
            i
            for box, score in zip(answer.predictions.boxes, scores, strict=True)
            if score >= threshold and (i := labelled.index_of(box)) is not None
        }
        with p.session.lock:
            current = p.editor.draft
            stale = generation is not None and generation != self._generation
            if stale or current.prompt.strip() != prompt or p.frame is not frame:
                return None
            p.editor.apply(self._with(current, labelled, chosen), "edit prompt", "prompt")
            if current.boxes or chosen:
                p.selected = p.editor.draft.boxes[0].box_id if p.editor.draft.boxes else None
            self.picked_for, self.auto = prompt, True
            p.refresh(Part.DRAFT)
        return len(chosen)

    @staticmethod
    def _with(draft: Draft, labelled: Labelled, chosen: set[int]) -> Draft:
        """``draft`` with exactly the ``chosen`` labelled boxes (its own boxes kept)."""
        have = {}
        for item in draft.boxes:
            index = labelled.index_of(item.box)
            if index is not None:
                have[index] = item.box_id
        out = draft
        for index, box_id in have.items():
            if index not in chosen:
                out = out.delete_box(box_id)
        new = sorted(chosen - set(have))
        if new:
            out = out.add_boxes(labelled.boxes[new], [labelled.classes[i] for i in new])
        return out

    def ready_to_save(self) -> bool:
        """Enter: whether the boxes were chosen for the sentence as it is now (else pick them
        now, show them, and say that the next Enter saves)."""
        p = self.panel
        with p.session.lock:
            prompt = p.editor.draft.prompt.strip()
        labelled = self.labelled()
        if not self.auto or labelled is None or self.picked_for == prompt:
            return True
        if any(labelled.index_of(b.box) is None for b in self.panel.editor.draft.boxes):
            return True  # boxes of the annotator's own: nothing is picked
        with self._lock:
            self._generation += 1
            if self._timer is not None:
                self._timer.cancel()
        future = p.session.engine.submit(self.pick)
        count = future.result(timeout=PICK_TIMEOUT_S)
        if count is not None:
            p.notify(
                "Referents picked",
                f"{count} labelled box(es) for the sentence: check them (a click toggles one), "
                "then Enter saves.",
                color="blue",
            )
        return False
