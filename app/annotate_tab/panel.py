"""The state of one browser's Annotate tab and how it is drawn: :class:`AnnotationPanel`.

The panel owns the tab's state (the :class:`annotate.DraftEditor`, the selected box, the draft's
frame) and draws it into the widgets and the scene. What the person does is handled by
:class:`app.annotate_tab.edits.DraftEdits` and :class:`app.annotate_tab.pairs.PairActions`, which
change the state and then ask for the :class:`Part` s that depend on what they changed
(:meth:`AnnotationPanel.refresh`): a keystroke in the prompt revalidates the draft but neither
redraws the boxes nor recounts the points in them; selecting a box redraws the boxes and the
evidence table but does not revalidate. The per-box evidence (:func:`annotate.box_evidence`, over
every LiDAR point of the frame) is computed again only when the boxes or the frame changed.

Ready-made boxes: on a root without prompts (a View-of-Delft root as released), ``label_2``
lists every object of the frame; its metric-class boxes that are not in the draft yet (no draft
box overlaps them by :data:`annotate.DUPLICATE_IOU` in bird's eye view) are offered
(:attr:`AnnotationPanel.ready_boxes`), drawn in the 3D view and listed under *Object*, nearest
first.
"""

from __future__ import annotations

import enum
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import viser

from annotate import (
    AnnotationStore,
    BoxEvidence,
    Draft,
    DraftEditor,
    StoreError,
    ValidationConfig,
    ValidationReport,
    box_evidence,
    changed_box,
    is_pristine,
    proposals,
    validate,
)
from app.annotate_tab.formatting import (
    NO_BOX,
    NO_PAIRS,
    NO_READY,
    box_option,
    checks_markdown,
    evidence_markdown,
    option_pair_id,
    pair_option,
    pairs_markdown,
    ready_option,
    status_markdown,
)
from app.annotate_tab.hub import AnnotationHub
from app.annotate_tab.labelled import Labelled, frame_labelled
from app.annotate_tab.view import DraftView, draft_layer
from app.annotate_tab.widgets import (
    AnnotationWidgets,
    build_annotation_widgets,
    selection_marker,
)
from app.annotate_tab.writes import ServerWrites
from app.session import ClientSession
from app.text import md_text
from scenes.frame import Sample

log = logging.getLogger(__name__)


PLACEMENT_FIELDS = (".position", ".image")
"""Validation fields of a box that say it cannot be saved where it is."""


class Part(enum.Flag):
    """The parts of the tab that :meth:`AnnotationPanel.refresh` brings up to date."""

    VIEW = enum.auto()
    """The draft boxes and the gizmo in the 3D view and the camera panel, the *Box* list and the
    selected box's inputs, the ready-made boxes."""
    EVIDENCE = enum.auto()
    """The evidence table (its numbers are recomputed only when the boxes or the frame changed)."""
    SENTENCE = enum.auto()
    """*Pair prompt* and *Refers to nothing*."""
    CHECKS = enum.auto()
    """Validation of the draft (above *Save pair*), and what may be saved (*Save*, *Split*)."""
    STATUS = enum.auto()
    """The status line (pair, frame, undo / redo) and *Back to the draft's frame*."""
    ANSWER = enum.auto()
    """*Use predictions* (an answer on the draft's frame is drawn)."""

    SELECTION = VIEW | EVIDENCE
    """What shows which box is selected."""
    TEXT = SENTENCE | CHECKS | STATUS
    """What depends on the prompt and its flag."""
    DRAFT = VIEW | EVIDENCE | SENTENCE | CHECKS | STATUS
    """Everything that shows the draft (any edit of its boxes, undo, redo)."""
    ALL = DRAFT | ANSWER
    """Everything (the draft's frame or the frame on screen changed)."""


@dataclass(frozen=True)
class DraftFrame:
    """The frame a draft is annotated on.

    Attributes:
        sample: Its sensors (LiDAR frame) and calibration.
        ground_z: Ground height (m, LiDAR frame) where clicks land and new boxes stand.
        sample_ids: The samples of the served root that show this frame (the sample itself;
            for a reopened pair also the frame it was annotated on).
    """

    sample: Sample
    ground_z: float
    sample_ids: frozenset[str]

    @property
    def name(self) -> str:
        return self.sample.sample_id


class AnnotationPanel:
    """The Annotate tab of one browser (see the module docstring and :mod:`app.annotate_tab`).

    Locking: everything that reads or changes the panel's state or draws holds
    ``session.lock`` (the lock the session holds while it draws frames and answers, so the order
    of locks is always the same); the store's work (saving, deleting) runs outside it, and so do
    moves of the shared frame (``session.go_to``, ``navigator.reload``), which take the
    navigator's lock first. The gizmo's callback runs on viser's event loop (in message order)
    and only touches the :class:`annotate.DraftEditor`, which has its own lock.

    Args:
        session: The browser's session.
        hub: The served root's store and open tabs.
    """

    def __init__(self, session: ClientSession, hub: AnnotationHub) -> None:
        self.session = session
        self.hub = hub
        self.navigator = session.navigator
        self.editor = DraftEditor()
        self.selected: int | None = None
        self.frame: DraftFrame | None = None
        self.view = DraftView(session.client.scene)
        self.classes: tuple[str, ...] = session.engine.classes.names
        """The served model's classes: what the class controls offer, keys and C cycle."""
        self.w: AnnotationWidgets = build_annotation_widgets(session.client.gui, self.classes)
        self.pair_ids: tuple[str, ...] = ()
        """The sample ids listed in *Pair*, in order."""
        self.ready_boxes: np.ndarray = np.zeros((0, 7))
        """``(R, 7)`` the ready-made boxes offered now (LiDAR frame), in *Object* order."""
        self.ready_classes: tuple[str, ...] = ()
        self.report: ValidationReport = ValidationReport()
        """The draft's last validation (what *Save pair*'s state shows)."""
        self.last_saved: str | None = None
        """What this browser's last save wrote, shown in the status line."""
        self.last_pair: tuple[Draft, DraftFrame] | None = None
        """The draft this browser saved last and its frame (what *Carry to next frame* carries
        once the draft was emptied by the save)."""
        self.writes = ServerWrites()
        """What the server last wrote into each edit widget (never over a pending edit)."""
        self._evidence: tuple[DraftFrame, tuple[object, ...], tuple[BoxEvidence, ...]] | None
        self._evidence = None
        """The last evidence computed: ``(frame, boxes, evidence)``."""
        self._labelled: tuple[DraftFrame, Labelled | None] | None = None
        self.note: Callable[[], str | None] = lambda: None
        """A line for the status (the referent picker's, :mod:`app.annotate_tab.referents`)."""
        self.referents_for: Callable[[], str | None] = lambda: None
        """The sentence the draft's labelled boxes were picked for (the referent picker's)."""

    # ------------------------------------------------------------------ state

    @property
    def store(self) -> AnnotationStore | None:
        return self.hub.store

    @property
    def draft(self) -> Draft:
        return self.editor.draft

    def config(self) -> ValidationConfig:
        """The rules the store checks before saving."""
        return self.store.validation if self.store is not None else ValidationConfig()

    def offers_ready(self) -> bool:
        """Whether the draft's frame offers ready-made boxes (its objects are labelled:
        :meth:`labelled`, or its root has no prompts, so its label_2 lists every object) and is
        on screen."""
        if self.frame is None or not self.on_screen():
            return False
        return self.frame.sample.prompt is None or self.labelled() is not None

    def placement_problems(self, box: Sequence[float], cls: str) -> list[str]:
        """Why a box could not be saved where it is on the draft's frame (outside the annotated
        range or the camera's view: :func:`annotate.validate`'s position and image rules)."""
        if self.frame is None:
            return []
        report = validate(Draft().add_box(box, cls), self.config(), self.frame.sample.calib)
        return [i.message for i in report.errors if i.field.endswith(PLACEMENT_FIELDS)]

    def labelled(self) -> Labelled | None:
        """The labelled boxes of the draft's frame that the referent stage can pick for a pair
        (:func:`~app.annotate_tab.labelled.frame_labelled`, read once per frame, without the
        boxes a pair could not hold; None: none, or a label file that cannot be read, which is
        logged)."""
        frame = self.frame
        if frame is None:
            return None
        cached = self._labelled
        if cached is None or cached[0] is not frame:
            try:
                found = frame_labelled(self.session.options, frame.sample)
            except Exception as exc:  # a malformed label file: the tab works without them
                log.error("labelled boxes of sample %s: %s", frame.name, exc)
                found = None
            if found is not None:  # only boxes a pair can hold (in range, in the image)
                keep = [
                    i
                    for i, (b, c) in enumerate(zip(found.boxes, found.classes, strict=True))
                    if not self.placement_problems(b, c)
                ]
                found = Labelled(found.boxes[keep], tuple(found.classes[i] for i in keep))
            cached = self._labelled = (frame, found)
        return cached[1]

    def on_screen(self) -> bool:
        """Whether the frame on screen is the draft's frame."""
        sample = self.session.sample
        return (
            sample is not None
            and self.frame is not None
            and sample.sample_id in self.frame.sample_ids
        )

    def bind_to_screen(self) -> None:
        """Make the frame on screen the draft's frame."""
        frame = self.session.frame
        if frame is not None:
            self.frame = DraftFrame(frame.sample, frame.ground_z, frozenset({frame.sample_id}))

    def select_changed(self, before: Draft, after: Draft) -> None:
        """Select the box an edit (undo, redo) added or changed, if any."""
        changed = changed_box(before, after)
        if changed is not None:
            self.selected = changed

    def notify(self, title: str, body: str, color: str = "yellow") -> None:
        self.session.notify(title, body, color=color, auto_close_seconds=10.0)

    # ------------------------------------------------------------------ drawing

    def refresh(self, parts: Part = Part.ALL, skip: object | None = None) -> None:
        """Bring ``parts`` of the tab up to date with the state (``skip``: a widget the person
        is editing, whose value must not be written back)."""
        with self.session.lock:
            if self.session.closed:
                return
            draft = self.editor.draft
            if self.selected not in draft.box_ids:
                self.selected = None
            visible = self.on_screen()
            w = self.w
            with self.session.client.atomic():
                if parts & Part.VIEW:
                    self.view.show(draft, self.selected, visible)
                    self._show_ready(draft)
                    self.session.set_camera_layer(
                        "draft", draft_layer(draft, self.selected, visible)
                    )
                if parts & Part.STATUS:
                    w.status.content = self._status(draft, visible)
                    self._show_split()
                    w.back.visible = (
                        not visible and self.frame is not None and not is_pristine(draft)
                    )
                if parts & Part.VIEW:
                    self._show_boxes(draft, skip)
                if parts & Part.ANSWER:
                    answer = self.session.answer
                    w.use_predictions.disabled = not visible or (
                        self.labelled() is None
                        and (answer is None or not len(answer.predictions.boxes))
                    )
                if parts & Part.EVIDENCE:
                    w.evidence.content = evidence_markdown(
                        draft, self._box_evidence(draft), self.selected
                    )
                if parts & Part.SENTENCE:
                    if w.prompt is not skip:
                        self.writes.show(w.prompt, draft.prompt)
                    w.nothing.value = draft.refers_to_nothing
                if parts & Part.CHECKS:
                    self._show_checks(draft)

    def _status(self, draft: Draft, visible: bool) -> str:
        return status_markdown(
            draft,
            self.editor.history,
            self.frame.name if self.frame is not None else None,
            visible,
            is_pristine(draft),
            unavailable=self.hub.error if self.store is None else None,
            saving_to=(self.hub.path, self.hub.served.pairs_described())
            if self.hub.separate
            else None,
            last_saved=self.last_saved,
            note=self.note(),
        )

    def pair_split(self) -> str | None:
        """The split a new pair on the draft's frame must go into (a Talk2Car command: its
        sample's, :meth:`app.serving.served.ServedRoot.pair_split`); None: the person's *Split*."""
        if self.frame is None or self.draft.sample_id is not None:
            return None
        return self.hub.served.pair_split(self.frame.sample)

    def _show_split(self) -> None:
        """*Split* shows a split the draft's frame fixes (it cannot be changed then:
        :meth:`_show_checks`)."""
        fixed, w = self.pair_split(), self.w
        if fixed is not None and fixed not in w.split.options:
            w.split.options = (*w.split.options, fixed)
        if fixed is not None and w.split.value != fixed:
            w.split.value = fixed

    def _show_ready(self, draft: Draft) -> None:
        """The ready-made boxes not in the draft: in the 3D view and the *Object* list."""
        w = self.w
        offered = self.offers_ready()
        if offered and self.frame is not None:
            sample = self.frame.sample
            labelled = self.labelled()
            source = (
                (labelled.boxes, labelled.classes)
                if labelled is not None
                else (sample.boxes, sample.classes)
            )
            boxes, classes, _ = proposals(
                *source, draft.box_array, limit=10**6, allowed=self.classes
            )
            order = np.argsort(np.hypot(boxes[:, 0], boxes[:, 1]), kind="stable")
            boxes, classes = boxes[order], tuple(classes[i] for i in order)
        else:
            boxes, classes = np.zeros((0, 7)), ()
        self.ready_boxes, self.ready_classes = boxes, classes
        self.view.show_ready(boxes, classes)
        self.view.ready.visible = self.session.others_visible  # the Query tab's group toggle
        options = tuple(
            ready_option(i, c, b) for i, (c, b) in enumerate(zip(classes, boxes, strict=True))
        )
        previous = w.ready.value
        w.ready.options = options or (NO_READY,)
        w.ready.value = previous if previous in options else (options or (NO_READY,))[0]
        for handle in w.ready_inputs():
            handle.visible = offered
        w.add_ready.disabled = not options

    def _show_boxes(self, draft: Draft, skip: object | None) -> None:
        """The *Box* list and the selected box's inputs (disabled while none is selected)."""
        w = self.w
        options = tuple(box_option(i, b.cls, b.box) for i, b in enumerate(draft.boxes))
        selected = None
        if self.selected is not None:
            index = draft.index_of(self.selected)
            selected = draft.boxes[index]
            self.writes.show_choice(w.box, (NO_BOX, *options), options[index])
        else:
            self.writes.show_choice(w.box, (NO_BOX, *options), NO_BOX)
        marker = selection_marker(selected is not None)
        if w.selection.content != marker:
            w.selection.content = marker
        for handle in w.box_inputs():
            handle.visible = selected is not None
        if selected is None:
            return
        length, width, height, yaw = selected.box[3:]
        for handle, value in (
            (w.length, length),
            (w.width, width),
            (w.height, height),
            (w.yaw, float(np.degrees(yaw))),
        ):
            if handle is not skip:
                self.writes.show(handle, round(float(value), 4))

    def _show_checks(self, draft: Draft) -> None:
        """Validate the draft; *Save pair* is enabled only when nothing blocks saving."""
        w = self.w
        calib = self.frame.sample.calib if self.frame is not None else None
        report = validate(draft, self.config(), calib)
        if (
            self.frame is not None
        ):  # what the root kind asks more (a Talk2Car command: one referent)
            extra = self.hub.served.draft_issues(draft, self.frame.sample)
            report = replace(report, issues=report.issues + extra) if extra else report
        self.report = report
        w.checks.content = checks_markdown(self.report, saving=self.store is not None)
        w.save.disabled = self.store is None or self.frame is None or not self.report.ok
        w.split.disabled = draft.sample_id is not None or self.pair_split() is not None

    def _box_evidence(self, draft: Draft) -> tuple[BoxEvidence, ...]:
        """The evidence of the draft's boxes on its frame (cached for the same frame and boxes)."""
        if self.frame is None or not draft.boxes:
            return ()
        frame, boxes = self.frame, tuple(b.box for b in draft.boxes)
        cached = self._evidence
        if cached is None or cached[0] is not frame or cached[1] != boxes:
            evidence = box_evidence(draft.box_array, frame.sample.lidar, frame.sample.radar)
            cached = self._evidence = (frame, boxes, tuple(evidence))
        return cached[2]

    def accept_edit(self, handle: viser.GuiInputHandle) -> None:
        """The browser's value of ``handle`` is being applied now (holding ``session.lock``): it
        is no longer a pending edit that a redraw must not overwrite (:class:`ServerWrites`)."""
        self.writes.accept(handle)

    def refresh_pairs(self) -> None:
        """Re-read the saved pairs of the root into the *Pair* dropdown and table; a pairs file
        that cannot be listed (a command that does not resolve against the root, a malformed
        file) is one line in the table and the log, and the tab keeps working."""
        problem = None
        try:
            pairs = self.store.pairs() if self.store is not None else ()
        except (StoreError, OSError, ValueError) as exc:
            pairs, problem = (), " ".join(str(exc).split())
            log.warning("saved pairs of %s cannot be listed: %s", self.hub.path, problem)
        with self.session.lock:
            if self.session.closed:
                return
            w = self.w
            previous = option_pair_id(w.pair.value)
            options = tuple(pair_option(p) for p in pairs)
            self.pair_ids = tuple(p.sample_id for p in pairs)
            w.pair.options = options or (NO_PAIRS,)
            if previous in self.pair_ids:
                w.pair.value = options[self.pair_ids.index(previous)]
            elif options:
                w.pair.value = options[-1]
            w.open_pair.disabled = w.delete_pair.disabled = not options
            w.pairs.content = (
                f"**Saved pairs cannot be listed:** {md_text(problem)}"
                if problem is not None
                else pairs_markdown(pairs, self.hub.path)
            )

    # ------------------------------------------------------------------ listeners

    def on_frame(self, session: ClientSession) -> None:
        """A new frame is on screen (called by the session, holding its lock)."""
        if self.frame is None or is_pristine(self.editor.draft):
            self.bind_to_screen()
        self.refresh()

    def on_answer(self, session: ClientSession) -> None:
        """A new answer is drawn: *Use predictions* may apply now."""
        self.refresh(Part.ANSWER)

    # ------------------------------------------------------------------ helpers

    def guarded(self, fn: Callable[[], None]) -> None:
        """Run a GUI action; an unexpected error becomes a notification, never a dead panel."""
        try:
            fn()
        except Exception as exc:
            self.session.report_error("Annotation error", exc)

    def confirm(self, title: str, text: str, action: str, fn: Callable[[], None]) -> None:
        """Ask in a modal window; ``fn`` runs when the person clicks ``action``."""
        gui = self.session.client.gui
        with gui.add_modal(title) as modal:
            gui.add_markdown(md_text(text))
            yes = gui.add_button(action, color="red")
            no = gui.add_button("Cancel")

        @yes.on_click
        def _(_: viser.GuiEvent) -> None:
            modal.close()
            self.guarded(fn)

        @no.on_click
        def _(_: viser.GuiEvent) -> None:
            modal.close()

    def back_to_draft_frame(self) -> None:
        """Show the draft's frame (in every browser: navigation is shared)."""
        with self.session.lock:
            frame = self.frame
        if frame is None:
            return
        frames = self.navigator.frames
        target = next((i for i, sid in enumerate(frames.ids) if sid in frame.sample_ids), None)
        if target is None:
            self.notify(
                "Frame not in this split",
                f"Sample {frame.name} is not in split '{frames.split}' being served.",
            )
            return
        self.session.go_to(target)
