"""The "Annotate" tab: build prompt-to-box pairs in the browser and save them into the served root.

A thin layer over :mod:`annotate` (drafts with undo / redo, validation, fitting, evidence, prompt
suggestion, the atomic store); nothing here re-implements them. :mod:`app.session` calls
:func:`build_annotation_tab` for every browser, inside its "Annotate" tab.

Per browser: an :class:`AnnotationPanel` with its own :class:`annotate.DraftEditor`, selection,
draft boxes and transform gizmo (:class:`app.annotation_view.DraftView`, in ``client.scene``).
Per served root, shared by every browser: one :class:`annotate.AnnotationStore`
(:func:`shared_root`). Pairs are saved into the root being served; after a save or a deletion
the app's split is re-read (:meth:`app.server.Talk2PCApp.reload_frames`) and every browser's list
of saved pairs is refreshed.

Using it with the mouse only:

- **Click the ground** (with *Click to place* on) to place a box of the *New box class* at its
  typical size (:func:`annotate.default_box`) standing on the frame's ground estimate; the new box
  is selected. A click inside a draft box's footprint selects that box instead.
- **Drag the gizmo** of the selected box: its arrows and square move it on the ground, its ring
  turns it (yaw). One drag is one undo step (:class:`annotate.DraftEditor`'s ``merge_key``).
- *Box* picks the selected box; *Class*, *Length*, *Width*, *Height*, *Yaw (deg)* edit it (the
  bottom stays on the ground when the height changes); *Fit to points* fits it to the LiDAR
  points around it (:func:`annotate.fit_box`); *Delete box* removes it. *Use predictions* turns
  the boxes of the last answer (Query tab) on this frame into draft boxes.
- The evidence table gives, per box, the LiDAR and radar points inside, the mean compensated
  radial velocity and what its sign means, and the distance (:func:`annotate.box_evidence`).
- *Pair prompt* holds the sentence; *Suggest* writes one from the boxes
  (:func:`annotate.suggest_prompt`), to edit; *Refers to nothing* marks a prompt with no referent.
- *Save pair* writes the pair (split and annotator name beside it); problems found by
  :func:`annotate.validate` are listed under it before saving and shown as a notification with
  the exact messages when saving is refused. *Draft*: Undo, Redo, New pair.
- *Saved pairs* lists the pairs of the root (re-read on every page load); *Open pair* reopens
  one into the draft (saving then writes a new version), *Delete pair* removes it (after a
  confirmation).

Hotkeys: viser 1.1.1 has experimental commands (``gui.add_command``) with hotkeys, also listed in
its command palette (Ctrl/Cmd+K). :data:`HOTKEYS` registers Undo, Redo, Delete box and Save pair.

The frame of a draft. Navigation is shared by every browser, so the frame on screen can change
under a draft. A draft belongs to the frame it was started on (for a reopened pair: the pair's
sample and the frame it was annotated on). While another frame is shown its boxes are hidden, a
click on the ground does nothing but say so, and *Back to the draft's frame* returns to it;
saving still saves it on its own frame. An empty draft simply follows the frame on screen.

After a successful save the draft is emptied (a new pair on the frame on screen).
"""

from __future__ import annotations

import asyncio
import logging
import threading
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import viser

from annotate import (
    AnnotationStore,
    BoxEvidence,
    BoxRegion,
    ConflictError,
    Draft,
    DraftEditor,
    DraftError,
    FitError,
    Motion,
    PairInfo,
    SceneObject,
    Severity,
    SourceFrame,
    StoreError,
    ValidationConfig,
    ValidationError,
    ValidationReport,
    box_evidence,
    default_box,
    fit_box,
    suggest_prompt,
    validate,
)
from annotate.store import DEFAULT_SPLITS
from app.annotation_view import DraftView, box_at, box_tag, ground_hit, wxyz_to_yaw
from app.scene_view import estimate_ground_z
from app.text import md_text
from scenes.actors import CLASSES, Actor
from scenes.boxes import bev_iou
from scenes.root import Sample

if TYPE_CHECKING:
    from app.session import ClientSession

log = logging.getLogger(__name__)

SPLITS = DEFAULT_SPLITS
"""Splits offered when saving (the store's default, ``train``, is selected); the store refuses any
other (a forged websocket message included)."""

NO_BOX = "(none)"
"""The *Box* dropdown's entry for "no box selected"."""

NO_PAIRS = "(no saved pairs)"
"""The *Pair* dropdown's only option while the root has no saved pair."""

MAX_PROPOSALS = 20
"""*Use predictions* adds at most this many boxes (the best scores)."""

DUPLICATE_IOU = 0.5
"""A predicted box overlapping a draft box at least this much (BEV IoU) is not added again."""

RECENT_PAIRS = 8
"""Saved pairs shown in the table under the *Pair* dropdown (the most recent)."""

MOTION_TEXT = {
    Motion.APPROACHING: "approaching",
    Motion.RECEDING: "moving away",
    Motion.STATIC: "static",
    Motion.UNKNOWN: "no radar",
}
"""How the sign of a box's mean compensated radial velocity reads in the evidence table."""

HOTKEYS: tuple[tuple[str, str, str | None, str], ...] = (
    ("undo", "Z", "cmd/ctrl", "Annotate: undo"),
    ("redo", "Z", "cmd/ctrl+shift", "Annotate: redo"),
    ("delete", "delete", None, "Annotate: delete the selected box"),
    ("save", "S", "cmd/ctrl+shift", "Annotate: save the pair"),
)
"""``(action, key, modifier, palette label)`` of the hotkeys."""


# ---------------------------------------------------------------------- the store, shared


class SharedRoot:
    """What every browser serving one root shares: the store and the open panels.

    Attributes:
        path: The root.
        store: Its :class:`annotate.AnnotationStore`, or None when it cannot be opened.
        error: Why the store could not be opened (None when it could).
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.store: AnnotationStore | None = None
        self.error: str | None = None
        try:
            self.store = AnnotationStore(path)
        except (OSError, StoreError, ValueError) as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            log.error("annotation store of %s unavailable: %s", path, self.error)
        self._panels: weakref.WeakValueDictionary[int, AnnotationPanel] = (
            weakref.WeakValueDictionary()
        )
        self._lock = threading.Lock()

    def register(self, panel: AnnotationPanel) -> None:
        """Keep ``panel`` informed of saved and deleted pairs (until its browser leaves)."""
        with self._lock:
            self._panels[id(panel)] = panel

    def panels(self) -> list[AnnotationPanel]:
        """The panels of the browsers still connected."""
        with self._lock:
            items = list(self._panels.values())
        return [p for p in items if not p.session.closed]

    def pairs_changed(self) -> None:
        """Re-list the saved pairs in every connected browser."""
        for panel in self.panels():
            try:
                panel.refresh_pairs()
            except Exception:  # One browser's failure must not stop the others' update.
                log.exception("client %s: could not re-list the pairs", panel.session.client_id)


_SHARED: dict[str, SharedRoot] = {}
_SHARED_LOCK = threading.Lock()


def shared_root(path: str | Path) -> SharedRoot:
    """The :class:`SharedRoot` of a root folder (one per resolved path in this process)."""
    key = str(Path(path).resolve())
    with _SHARED_LOCK:
        if key not in _SHARED:
            _SHARED[key] = SharedRoot(Path(path))
        return _SHARED[key]


# ---------------------------------------------------------------------- pure helpers


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


def is_pristine(draft: Draft) -> bool:
    """Whether a draft holds nothing worth keeping (a new pair, no box, no prompt, no mark)."""
    return (
        draft.sample_id is None
        and not draft.boxes
        and not draft.prompt.strip()
        and not draft.refers_to_nothing
    )


def changed_box(before: Draft, after: Draft) -> int | None:
    """The id of the first box of ``after`` that is new or differs from ``before`` (None when
    no box was added or changed, e.g. after a deletion)."""
    old = {b.box_id: b for b in before.boxes}
    for item in after.boxes:
        if old.get(item.box_id) != item:
            return item.box_id
    return None


def proposals(
    boxes: np.ndarray,
    classes: Sequence[str],
    existing: np.ndarray,
    limit: int = MAX_PROPOSALS,
    duplicate_iou: float = DUPLICATE_IOU,
) -> tuple[np.ndarray, tuple[str, ...], int]:
    """The predicted boxes to add to a draft.

    Args:
        boxes: ``(K, 7)`` predicted boxes, LiDAR frame, best score first.
        classes: Their ``K`` classes.
        existing: ``(E, 7)`` boxes already in the draft.
        limit: Most boxes returned.
        duplicate_iou: A box overlapping an existing (or an earlier returned) box at least this
            much in bird's eye view is a duplicate and left out.

    Returns:
        ``(boxes (P, 7), classes, duplicates)``: the boxes to add, in score order, their classes
        (metric classes only), and how many were left out as duplicates.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    kept = np.asarray(existing, dtype=np.float64).reshape(-1, 7)
    out: list[int] = []
    duplicates = 0
    for k in range(len(b)):
        if len(out) >= limit:
            break
        if classes[k] not in CLASSES or np.any(b[k, 3:6] <= 0):
            continue
        if len(kept) and float(bev_iou(b[k : k + 1], kept).max()) >= duplicate_iou:
            duplicates += 1
            continue
        out.append(k)
        kept = np.concatenate([kept, b[k : k + 1]])
    return b[out], tuple(str(classes[k]) for k in out), duplicates


def scene_objects(sample: Sample) -> list[Actor | SceneObject]:
    """The objects of a frame a suggested prompt must tell the draft boxes apart from: the
    sidecar's actors (with velocities) when the sample has one, else its labelled boxes."""
    if sample.meta is not None and sample.meta.actors:
        return list(sample.meta.actors)
    return [
        SceneObject(tuple(float(v) for v in box), cls)
        for box, cls in zip(np.asarray(sample.boxes).reshape(-1, 7), sample.classes, strict=True)
    ]


def box_option(index: int, cls: str, box: Sequence[float]) -> str:
    """The *Box* dropdown entry of draft box ``index``: ``"#2 Car · 14.1 m"``."""
    return f"{box_tag(index, cls)} · {float(np.hypot(box[0], box[1])):.1f} m"


def option_index(option: str) -> int | None:
    """The 0-based box index of a :func:`box_option` entry (None for :data:`NO_BOX`)."""
    head = option.split(" ", 1)[0]
    if head.startswith("#") and head[1:].isdigit():
        return int(head[1:]) - 1
    return None


def pair_option(pair: PairInfo) -> str:
    """The *Pair* dropdown entry of a saved pair: ``"00061 · 2 boxes · the cars ahead"``."""
    prompt = pair.prompt if len(pair.prompt) <= 48 else pair.prompt[:47] + "…"
    boxes = "1 box" if pair.num_boxes == 1 else f"{pair.num_boxes} boxes"
    return f"{pair.sample_id} · {boxes} · {prompt}"


def option_pair_id(option: str) -> str | None:
    """The sample id of a :func:`pair_option` entry (None for :data:`NO_PAIRS`)."""
    head = option.split(" ", 1)[0]
    return head if head.isdigit() else None


def evidence_markdown(
    draft: Draft, evidence: Sequence[BoxEvidence], selected_id: int | None
) -> str:
    """The evidence table: one row per box (the selected one in bold)."""
    if not draft.boxes:
        return "*No boxes yet: click the ground to place one.*"
    rows = [
        "| box | LiDAR | radar | mean v<sub>r</sub> | motion | dist |",
        "| --- | ---: | ---: | ---: | --- | ---: |",
    ]
    for i, (item, ev) in enumerate(zip(draft.boxes, evidence, strict=True)):
        v = "-" if ev.mean_radial_velocity is None else f"{ev.mean_radial_velocity:+.1f} m/s"
        cells = [
            md_text(box_tag(i, item.cls)),
            str(ev.lidar_points),
            str(ev.radar_points),
            v,
            MOTION_TEXT[ev.motion],
            f"{ev.distance:.1f} m",
        ]
        if item.box_id == selected_id:
            cells = [f"**{c}**" for c in cells]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def checks_markdown(report: ValidationReport) -> str:
    """What validation says about the draft, shown above *Save pair*."""
    lines = []
    if report.ok:
        lines.append("**Ready to save.**")
    else:
        lines.append("**Before saving:**")
        lines += [f"- {md_text(m)}" for m in report.messages()]
    warnings = report.messages(Severity.WARNING)
    if warnings:
        lines.append("**Warnings** (saving is allowed):")
        lines += [f"- {md_text(m)}" for m in warnings]
    return "\n".join(lines)


def pairs_markdown(pairs: Sequence[PairInfo], root: Path, limit: int = RECENT_PAIRS) -> str:
    """The table of the most recently saved pairs (every stored text escaped)."""
    if not pairs:
        return f"*No pair saved in {md_text(root)} yet.*"
    recent = sorted(pairs, key=lambda p: p.time, reverse=True)[:limit]
    rows = [
        f"{len(pairs)} saved pair(s) in {md_text(root)}; the latest:",
        "",
        "| id | v | split | boxes | prompt | by |",
        "| --- | ---: | --- | ---: | --- | --- |",
    ]
    for p in recent:
        rows.append(
            f"| {md_text(p.sample_id)} | {p.version} | {md_text(', '.join(p.splits))} | "
            f"{p.num_boxes} | {md_text(p.prompt)} | {md_text(p.annotator)} |"
        )
    return "\n".join(rows)


# ---------------------------------------------------------------------- widgets


@dataclass(frozen=True)
class AnnotationWidgets:
    """Handles of the Annotate tab (built by :func:`build_annotation_widgets`)."""

    status: viser.GuiMarkdownHandle
    back: viser.GuiButtonHandle
    place: viser.GuiCheckboxHandle
    new_class: viser.GuiDropdownHandle
    box: viser.GuiDropdownHandle
    cls: viser.GuiDropdownHandle
    length: viser.GuiNumberHandle
    width: viser.GuiNumberHandle
    height: viser.GuiNumberHandle
    yaw: viser.GuiNumberHandle
    fit: viser.GuiButtonHandle
    delete: viser.GuiButtonHandle
    use_predictions: viser.GuiButtonHandle
    evidence: viser.GuiMarkdownHandle
    prompt: viser.GuiTextHandle
    suggest: viser.GuiButtonHandle
    nothing: viser.GuiCheckboxHandle
    split: viser.GuiDropdownHandle
    annotator: viser.GuiTextHandle
    checks: viser.GuiMarkdownHandle
    save: viser.GuiButtonHandle
    draft: viser.GuiButtonGroupHandle
    pair: viser.GuiDropdownHandle
    open_pair: viser.GuiButtonHandle
    delete_pair: viser.GuiButtonHandle
    pairs: viser.GuiMarkdownHandle

    def box_inputs(self) -> tuple[viser.GuiInputHandle, ...]:
        """The inputs that edit the selected box (disabled while none is selected)."""
        return (self.cls, self.length, self.width, self.height, self.yaw, self.fit, self.delete)


UNDO, REDO, NEW_PAIR = "Undo", "Redo", "New pair"
"""Buttons of the *Draft* group."""


def build_annotation_widgets(gui: viser.GuiApi) -> AnnotationWidgets:
    """Add the Annotate tab's widgets to ``gui`` (in the current container)."""
    status = gui.add_markdown("Loading...")
    back = gui.add_button("Back to the draft's frame", icon=viser.Icon.ARROW_BACK, visible=False)
    place = gui.add_checkbox(
        "Click to place",
        True,
        hint="A click on the ground places a box of the class below; a click on a draft box "
        "selects it",
    )
    new_class = gui.add_dropdown("New box class", CLASSES, initial_value=CLASSES[0])
    with gui.add_folder("Boxes"):
        box = gui.add_dropdown("Box", (NO_BOX,), initial_value=NO_BOX)
        cls = gui.add_dropdown("Class", CLASSES, initial_value=CLASSES[0], disabled=True)
        size = {"min": 0.1, "max": 20.0, "step": 0.05, "disabled": True}
        length = gui.add_number("Length (m)", 4.2, hint="Along the heading", **size)
        width = gui.add_number("Width (m)", 1.8, **size)
        height = gui.add_number("Height (m)", 1.5, hint="The bottom stays on the ground", **size)
        yaw = gui.add_number(
            "Yaw (deg)",
            0.0,
            min=-180.0,
            max=180.0,
            step=1.0,
            disabled=True,
            hint="Counter-clockwise from forward (+x); the gizmo's ring turns it too",
        )
        fit = gui.add_button(
            "Fit to points",
            icon=viser.Icon.BOX_MODEL,
            disabled=True,
            hint="Fit centre, size and yaw to the LiDAR points in and around the box",
        )
        delete = gui.add_button("Delete box", icon=viser.Icon.TRASH, disabled=True)
        use_predictions = gui.add_button(
            "Use predictions",
            icon=viser.Icon.WAND,
            disabled=True,
            hint="The boxes of the last answer (Query tab) become draft boxes",
        )
        evidence = gui.add_markdown("")
    with gui.add_folder("Sentence"):
        prompt = gui.add_text("Pair prompt", "", hint="The sentence that refers to the boxes")
        suggest = gui.add_button(
            "Suggest", icon=viser.Icon.BULB, hint="Write a Talk2Radar-style prompt for the boxes"
        )
        nothing = gui.add_checkbox(
            "Refers to nothing", False, hint="The prompt describes no object of this frame"
        )
    with gui.add_folder("Save"):
        split = gui.add_dropdown("Split", SPLITS, initial_value=SPLITS[0])
        annotator = gui.add_text("Annotator", "", hint="Your name, recorded with the pair")
        checks = gui.add_markdown("")
        save = gui.add_button("Save pair", color="green", icon=viser.Icon.DEVICE_FLOPPY)
        draft = gui.add_button_group("Draft", (UNDO, REDO, NEW_PAIR))
    with gui.add_folder("Saved pairs"):
        pair = gui.add_dropdown("Pair", (NO_PAIRS,), initial_value=NO_PAIRS)
        open_pair = gui.add_button("Open pair", icon=viser.Icon.FOLDER_OPEN, disabled=True)
        delete_pair = gui.add_button("Delete pair", icon=viser.Icon.TRASH, disabled=True)
        pairs = gui.add_markdown("")
    return AnnotationWidgets(
        status=status,
        back=back,
        place=place,
        new_class=new_class,
        box=box,
        cls=cls,
        length=length,
        width=width,
        height=height,
        yaw=yaw,
        fit=fit,
        delete=delete,
        use_predictions=use_predictions,
        evidence=evidence,
        prompt=prompt,
        suggest=suggest,
        nothing=nothing,
        split=split,
        annotator=annotator,
        checks=checks,
        save=save,
        draft=draft,
        pair=pair,
        open_pair=open_pair,
        delete_pair=delete_pair,
        pairs=pairs,
    )


# ---------------------------------------------------------------------- the panel


def _from_browser(event: viser.GuiEvent) -> bool:
    """Whether a GUI event came from the browser (not from the server setting a value)."""
    return event.client is not None


class AnnotationPanel:
    """The Annotate tab of one browser (see the module docstring).

    Locking: everything that reads or changes the panel's state or draws holds
    ``session.lock`` (the lock the session holds while it draws frames and answers, so the order
    of locks is always the same); the store's work (saving, deleting) runs outside it, and so do
    calls into the app's navigation (``reload_frames``, ``go_to``), which take the app's lock
    first. The gizmo's callback runs on viser's event loop (in message order) and only touches
    the :class:`annotate.DraftEditor`, which has its own lock.

    Args:
        session: The browser's session.
        shared: The served root's store and panels.
    """

    def __init__(self, session: ClientSession, shared: SharedRoot) -> None:
        self.session = session
        self.app = session.app
        self.shared = shared
        self.editor = DraftEditor()
        self.selected: int | None = None
        self.frame: DraftFrame | None = None
        self.view = DraftView(session.client.scene)
        self.w = build_annotation_widgets(session.client.gui)
        self._drag = 0
        self._suggestions = 0
        self._pair_ids: tuple[str, ...] = ()
        self._shown: dict[int, object] = {}
        """The value the server last wrote into each edit widget (by ``id``), see :meth:`_show`."""
        self._wire()
        self._register_hotkeys()
        shared.register(self)
        self.refresh_pairs()
        self.refresh()

    # ------------------------------------------------------------------ state

    @property
    def store(self) -> AnnotationStore | None:
        return self.shared.store

    @property
    def draft(self) -> Draft:
        return self.editor.draft

    def on_screen(self) -> bool:
        """Whether the frame on screen is the draft's frame."""
        sample = self.session.sample
        return (
            sample is not None
            and self.frame is not None
            and sample.sample_id in self.frame.sample_ids
        )

    def _bind_to_screen(self) -> None:
        frame = self.session.frame
        if frame is not None:
            self.frame = DraftFrame(frame.sample, frame.ground_z, frozenset({frame.sample_id}))

    def notify(self, title: str, body: str, color: str = "yellow") -> None:
        self.session.notify(title, body, color=color, auto_close_seconds=10.0)

    # ------------------------------------------------------------------ refresh

    def refresh(self, skip: object | None = None) -> None:
        """Redraw the draft and bring every widget up to date (``skip``: a widget the person is
        editing, whose value must not be written back)."""
        with self.session.lock:
            if self.session.closed:
                return
            draft = self.editor.draft
            if self.selected not in draft.box_ids:
                self.selected = None
            visible = self.on_screen()
            evidence: tuple[BoxEvidence, ...] = ()
            if self.frame is not None and draft.boxes:
                evidence = box_evidence(
                    draft.box_array, self.frame.sample.lidar, self.frame.sample.radar
                )
            with self.session.client.atomic():
                self.view.show(draft, self.selected, visible)
                self._update_widgets(draft, evidence, visible, skip)

    def _update_widgets(
        self, draft: Draft, evidence: Sequence[BoxEvidence], visible: bool, skip: object | None
    ) -> None:
        w = self.w
        w.status.content = self._status_markdown(draft, visible)
        w.back.visible = not visible and self.frame is not None and not is_pristine(draft)
        options = tuple(box_option(i, b.cls, b.box) for i, b in enumerate(draft.boxes))
        w.box.options = (NO_BOX, *options)
        selected = None
        if self.selected is not None:
            index = draft.index_of(self.selected)
            selected = draft.boxes[index]
            w.box.value = options[index]
        else:
            w.box.value = NO_BOX
        for handle in w.box_inputs():
            handle.disabled = selected is None
        if selected is not None:
            length, width, height, yaw = selected.box[3:]
            if selected.cls in CLASSES and w.cls is not skip:
                self._show(w.cls, selected.cls)
            for handle, value in (
                (w.length, length),
                (w.width, width),
                (w.height, height),
                (w.yaw, float(np.degrees(yaw))),
            ):
                if handle is not skip:
                    self._show(handle, round(float(value), 4))
        answer = self.session.answer
        w.use_predictions.disabled = not (
            visible and answer is not None and len(answer.predictions.boxes) > 0
        )
        w.evidence.content = evidence_markdown(draft, evidence, self.selected)
        if w.prompt is not skip:
            self._show(w.prompt, draft.prompt)
        w.nothing.value = draft.refers_to_nothing
        calib = self.frame.sample.calib if self.frame is not None else None
        config = self.store.validation if self.store is not None else ValidationConfig()
        w.checks.content = checks_markdown(validate(draft, config, calib))
        w.save.disabled = self.store is None or self.frame is None
        w.split.disabled = draft.sample_id is not None

    def _show(self, handle: viser.GuiInputHandle, value: object) -> None:
        """Write the draft's ``value`` into an edit widget, unless the browser has changed the widget
        since the server last wrote it: that edit's callback is still queued behind the one running
        now (viser runs callbacks on worker threads, and they read the widget's value when they
        run), and writing the draft's older value would silently undo what the user typed."""
        key = id(handle)
        if key in self._shown and handle.value != self._shown[key]:
            return
        handle.value = value
        self._shown[key] = handle.value

    def _status_markdown(self, draft: Draft, visible: bool) -> str:
        lines = []
        if self.store is None:
            lines.append(f"**Saving is unavailable:** {md_text(self.shared.error)}")
        frame = self.frame
        if draft.sample_id is not None:
            lines.append(
                f"**Editing pair {md_text(draft.sample_id)}** (version {draft.base_version}); "
                f"*Save pair* writes version {draft.base_version + 1}."
            )
        elif frame is not None:
            lines.append(f"**New pair** on sample {md_text(frame.name)}.")
        if frame is not None and not visible and not is_pristine(draft):
            lines.append(
                f"This draft belongs to sample {md_text(frame.name)}, not to the frame on screen: its "
                "boxes are hidden. *Back to the draft's frame* shows it; *New pair* starts over."
            )
        history = self.editor.history
        undo = history.undo_label if history.can_undo else "-"
        redo = history.redo_label if history.can_redo else "-"
        lines.append(f"Undo: *{md_text(undo)}* · Redo: *{md_text(redo)}*")
        return "  \n".join(lines)

    def refresh_pairs(self) -> None:
        """Re-read the saved pairs of the root into the *Pair* dropdown and table."""
        pairs = self.store.pairs() if self.store is not None else ()
        with self.session.lock:
            if self.session.closed:
                return
            w = self.w
            previous = option_pair_id(w.pair.value)
            options = tuple(pair_option(p) for p in pairs)
            self._pair_ids = tuple(p.sample_id for p in pairs)
            w.pair.options = options or (NO_PAIRS,)
            if previous in self._pair_ids:
                w.pair.value = options[self._pair_ids.index(previous)]
            elif options:
                w.pair.value = options[-1]
            w.open_pair.disabled = w.delete_pair.disabled = not options
            w.pairs.content = pairs_markdown(pairs, self.shared.path)

    # ------------------------------------------------------------------ listeners

    def on_frame(self, session: ClientSession) -> None:
        """A new frame is on screen (called by the session, holding its lock)."""
        if self.frame is None or is_pristine(self.editor.draft):
            self._bind_to_screen()
        self.refresh()

    def on_answer(self, session: ClientSession) -> None:
        """A new answer is drawn: *Use predictions* may apply now."""
        self.refresh()

    # ------------------------------------------------------------------ wiring

    def _wire(self) -> None:
        w = self.w
        scene = self.session.client.scene
        scene.on_click()(self._on_click)
        self.view.gizmo.on_update(self._on_gizmo)

        def on_user(handle: viser.GuiInputHandle, fn: Callable[[], None]) -> None:
            def callback(event: viser.GuiEvent) -> None:
                if _from_browser(event):
                    with self.session.lock:  # reentrant; fn takes it too
                        # From here on no other callback can write the widget, and fn reads
                        # and applies this value: it is no longer a pending edit (see _show).
                        self._shown[id(handle)] = handle.value
                        self._guarded(fn)

            handle.on_update(callback)

        def on_click(handle: viser.GuiButtonHandle, fn: Callable[[], None]) -> None:
            handle.on_click(lambda _event: self._guarded(fn))

        on_user(w.box, self._select_from_list)
        on_user(w.cls, self._set_class)
        for handle in (w.length, w.width, w.height):
            on_user(handle, lambda h=handle: self._resize(h))
        on_user(w.yaw, self._set_yaw)
        on_user(w.prompt, self._set_prompt)
        on_user(w.nothing, self._set_nothing)
        on_click(w.fit, self.fit_selected)
        on_click(w.delete, self.delete_selected)
        on_click(w.use_predictions, self.use_predictions)
        on_click(w.suggest, self.suggest)
        on_click(w.save, self.save)
        on_click(w.open_pair, self.open_selected_pair)
        on_click(w.delete_pair, self.delete_selected_pair)
        on_click(w.back, self.back_to_draft_frame)

        @w.draft.on_click
        def _(event: viser.GuiEvent) -> None:
            action = {UNDO: self.undo, REDO: self.redo, NEW_PAIR: self.new_pair}.get(
                event.target.value
            )
            if action is not None:
                self._guarded(action)

    def _register_hotkeys(self) -> None:
        actions = {
            "undo": self.undo,
            "redo": self.redo,
            "delete": self.delete_selected,
            "save": self.save,
        }
        gui = self.session.client.gui
        for action, key, modifier, label in HOTKEYS:
            try:
                command = gui.add_command(label, hotkey=key, modifier=modifier)  # type: ignore[arg-type]
            except Exception as exc:  # Experimental in viser 1.1.1: the panel works without.
                log.warning("hotkey %s unavailable: %s", label, exc)
                return
            fn = actions[action]
            command.on_trigger(lambda _event, fn=fn: self._guarded(fn))

    def _guarded(self, fn: Callable[[], None]) -> None:
        """Run a GUI action; an unexpected error becomes a notification, never a dead panel."""
        try:
            fn()
        except Exception as exc:
            self.session.report_error("Annotation error", exc)

    # ------------------------------------------------------------------ scene interaction

    def _on_click(self, event: viser.SceneClickEvent) -> None:
        self._guarded(lambda: self.click_ground(event.ray_origin, event.ray_direction))

    def click_ground(self, ray_origin: Sequence[float], ray_direction: Sequence[float]) -> None:
        """A click in the 3D view: place a box where the ray meets the ground, or select the
        draft box there."""
        if not self.w.place.value:
            return
        with self.session.lock:
            if self.frame is None:
                return
            if not self.on_screen():
                self.notify(
                    "The draft is on another frame",
                    f"This draft belongs to sample {self.frame.name}. Go back to its frame "
                    "(button in the Annotate tab) or start a new pair.",
                )
                return
            hit = ground_hit(ray_origin, ray_direction, self.frame.ground_z)
            if hit is None:
                self.notify("Click on the ground", "That click did not hit the ground nearby.")
                return
            draft = self.editor.draft
            index = box_at(draft.box_array, *hit)
            if index is not None:
                self.selected = draft.boxes[index].box_id
            else:
                cls = self.w.new_class.value
                box = default_box(cls, hit[0], hit[1], self.frame.ground_z)
                self.selected = self.editor.add_box(box, cls)
            self.refresh()

    async def _on_gizmo(self, event: viser.TransformControlsEvent) -> None:
        """A gizmo drag (on the event loop, in message order): one undo step per drag."""
        box_id = self.view.gizmo_box_id
        if box_id is None:
            return
        if event.phase == "start":
            self._drag += 1
            return
        key = ("gizmo", box_id, self._drag)
        x, y, _ = (float(v) for v in event.target.position)
        yaw = wxyz_to_yaw(event.target.wxyz)
        try:
            self.editor.move_box(box_id, x, y, merge_key=key)
            self.editor.rotate_box(box_id, yaw, merge_key=key)
        except DraftError:  # The box went away (undo in another callback): drop the drag.
            return
        if event.phase == "end":  # Redraw in a worker thread; the loop goes on at once.
            asyncio.get_running_loop().run_in_executor(None, self._guarded, self.refresh)

    # ------------------------------------------------------------------ box edits

    def _select_from_list(self) -> None:
        with self.session.lock:
            index = option_index(self.w.box.value)
            draft = self.editor.draft
            if index is None:
                self.selected = None
            elif index < len(draft.boxes):
                self.selected = draft.boxes[index].box_id
            self.refresh()

    def _set_class(self) -> None:
        with self.session.lock:
            if self.selected is not None:
                self.editor.set_class(self.selected, self.w.cls.value)
            self.refresh()

    def _resize(self, source: viser.GuiNumberHandle) -> None:
        with self.session.lock:
            if self.selected is not None:
                w = self.w
                self.editor.resize_box(
                    self.selected,
                    float(w.length.value),
                    float(w.width.value),
                    float(w.height.value),
                    merge_key=("size", self.selected),
                )
            self.refresh(skip=source)

    def _set_yaw(self) -> None:
        with self.session.lock:
            if self.selected is not None:
                yaw = float(np.radians(float(self.w.yaw.value)))
                self.editor.rotate_box(self.selected, yaw, merge_key=("yaw", self.selected))
            self.refresh(skip=self.w.yaw)

    def _set_prompt(self) -> None:
        with self.session.lock:
            self.editor.set_prompt(self.w.prompt.value)
            self.refresh(skip=self.w.prompt)

    def _set_nothing(self) -> None:
        with self.session.lock:
            self.editor.set_refers_to_nothing(bool(self.w.nothing.value))
            self.refresh()

    def fit_selected(self) -> None:
        """Fit the selected box to the LiDAR points in and around it."""
        with self.session.lock:
            if self.selected is None or self.frame is None:
                return
            draft = self.editor.draft
            index = draft.index_of(self.selected)
            try:
                result = fit_box(self.frame.sample.lidar, BoxRegion(draft.boxes[index].box))
            except (FitError, ValueError) as exc:
                self.notify("Cannot fit the box", str(exc))
                return
            self.editor.set_box(
                self.selected, result.box, label=f"fit {box_tag(index, '')}".strip()
            )
            length, width, height = result.box[3:6]
            self.notify(
                "Box fitted",
                f"{box_tag(index, draft.boxes[index].cls)} fitted to {result.num_points} LiDAR "
                f"points: {length:.2f} x {width:.2f} x {height:.2f} m.",
                color="green",
            )
            self.refresh()

    def delete_selected(self) -> None:
        """Delete the selected box (undoable)."""
        with self.session.lock:
            if self.selected is None:
                return
            self.editor.delete_box(self.selected)
            self.selected = None
            self.refresh()

    def use_predictions(self) -> None:
        """Add the last answer's boxes on this frame to the draft (one undo step)."""
        with self.session.lock:
            answer = self.session.answer
            if answer is None:
                self.notify(
                    "No answer to use", "Run a prompt in the Query tab first; its boxes are added."
                )
                return
            if self.frame is None or answer.sample_id not in self.frame.sample_ids:
                self.notify(
                    "The answer is for another frame",
                    "Run the prompt again on the draft's frame.",
                )
                return
            pred = answer.predictions
            boxes, classes, duplicates = proposals(
                pred.boxes, pred.classes, self.editor.draft.box_array
            )
            if not len(boxes):
                self.notify(
                    "No new boxes", "Every predicted box is already in the draft (or none fits)."
                )
                return
            ids = self.editor.add_boxes(boxes, classes)
            self.selected = ids[0]
            extra = f"; {duplicates} already in the draft" if duplicates else ""
            self.notify(
                "Predicted boxes added",
                f"{len(ids)} of {len(pred.boxes)} predicted box(es) added{extra}.",
                color="green",
            )
            self.refresh()

    def suggest(self) -> None:
        """Write a suggested prompt for the boxes into *Pair prompt* (undoable)."""
        with self.session.lock:
            if self.frame is None:
                return
            draft = self.editor.draft
            self._suggestions += 1
            sample = self.frame.sample
            suggestion = suggest_prompt(
                draft.box_array,
                draft.classes,
                scene_objects(sample),
                sample.radar,
                np.random.default_rng(self._suggestions),
            )
            if suggestion.text is None:
                self.notify("No suggestion", suggestion.reason or "no sentence fits these boxes")
                return
            self.editor.set_prompt(suggestion.text, merge_key=None)
            self.refresh()

    # ------------------------------------------------------------------ draft actions

    def undo(self) -> None:
        """Take back the last edit; the box it changed (if still there) becomes selected."""
        with self.session.lock:
            before = self.editor.draft
            self._select_changed(before, self.editor.undo())
            self.refresh()

    def redo(self) -> None:
        """Re-apply the last undone edit; the box it changed becomes selected."""
        with self.session.lock:
            before = self.editor.draft
            self._select_changed(before, self.editor.redo())
            self.refresh()

    def _select_changed(self, before: Draft, after: Draft) -> None:
        changed = changed_box(before, after)
        if changed is not None:
            self.selected = changed

    def new_pair(self) -> None:
        """Start a new pair on the frame on screen (asks first when there are unsaved edits)."""
        if self.editor.history.can_undo and not is_pristine(self.editor.draft):
            self._confirm(
                "Discard the draft?",
                "The draft has unsaved changes. Start a new pair and discard them?",
                "Discard the draft",
                self._reset_draft,
            )
        else:
            self._reset_draft()

    def _reset_draft(self) -> None:
        with self.session.lock:
            self.editor.reset()
            self.selected = None
            self._bind_to_screen()
            self.refresh()

    def back_to_draft_frame(self) -> None:
        """Show the draft's frame (in every browser: navigation is shared)."""
        with self.session.lock:
            frame = self.frame
        if frame is None:
            return
        ids = self.app.frames.ids
        target = next((i for i, sid in enumerate(ids) if sid in frame.sample_ids), None)
        if target is None:
            self.notify(
                "Frame not in this split",
                f"Sample {frame.name} is not in split '{self.app.frames.split}' being served.",
            )
            return
        self.app.go_to(target, requester=self.session)

    # ------------------------------------------------------------------ saving

    def save(self) -> None:
        """Save the draft (a new pair, or a new version of the reopened pair)."""
        store = self.store
        with self.session.lock:
            draft, frame = self.editor.draft, self.frame
            split, annotator = self.w.split.value, self.w.annotator.value
        if store is None:
            self.notify("Saving is unavailable", str(self.shared.error), color="red")
            return
        if frame is None:
            return
        root = self.app.frames.root
        try:
            source = None
            if draft.sample_id is None:
                source = SourceFrame.from_root(root, frame.sample.sample_id, sample=frame.sample)
            result = store.save(draft, source, annotator=annotator, split=split)
        except ValidationError as exc:
            self.notify(
                "Cannot save the pair", "\n".join(i.message for i in exc.issues), color="red"
            )
            return
        except ConflictError as exc:
            self.notify("The pair changed meanwhile", str(exc), color="red")
            return
        except (StoreError, OSError, ValueError) as exc:
            log.error("client %s: save failed: %s", self.session.client_id, exc)
            self.notify("Save failed", str(exc), color="red")
            return
        warnings = "".join(f"\n{w.message}" for w in result.warnings)
        where = "new pair" if result.version == 1 else f"version {result.version}"
        self.notify(
            f"Saved pair {result.sample_id}",
            f"{where} in {', '.join(result.record.splits)} of {store.path}.{warnings}",
            color="green",
        )
        log.info(
            "client %s: saved pair %s v%d", self.session.client_id, result.sample_id, result.version
        )
        with self.session.lock:
            self.editor.reset()
            self.selected = None
            self._bind_to_screen()
        self._after_store_change()

    def _after_store_change(self) -> None:
        if Path(self.store.path).resolve() == Path(self.app.frames.root.path).resolve():
            try:
                self.app.reload_frames()
            except Exception as exc:
                self.session.report_error("Could not re-read the split", exc)
        self.shared.pairs_changed()
        self.refresh()

    def _selected_pair(self) -> str | None:
        sid = option_pair_id(self.w.pair.value)
        return sid if sid in self._pair_ids else None

    def open_selected_pair(self) -> None:
        """Reopen the pair chosen in *Pair* into the draft (asks first about unsaved edits)."""
        sid = self._selected_pair()
        if sid is None:
            return
        if self.editor.history.can_undo and not is_pristine(self.editor.draft):
            self._confirm(
                f"Open pair {sid}?",
                "The draft has unsaved changes. Open the pair and discard them?",
                "Discard and open",
                lambda: self.open_pair(sid),
            )
        else:
            self.open_pair(sid)

    def open_pair(self, sample_id: str) -> None:
        """Reopen a saved pair for editing and show its frame."""
        store = self.store
        if store is None:
            return
        root = self.app.frames.root
        try:
            draft = store.open(sample_id)
            sample = root.load(sample_id)
        except (StoreError, OSError, ValueError) as exc:
            self.notify(f"Cannot open pair {sample_id}", str(exc), color="red")
            return
        ids = {sample_id}
        history = store.history(sample_id)
        source = dict(history[-1].source) if history else {}
        same_root = bool(source.get("root")) and (
            Path(str(source["root"])).resolve() == Path(root.path).resolve()
        )
        if same_root and source.get("sample_id"):
            ids.add(str(source["sample_id"]))
        with self.session.lock:
            self.editor.reset(draft)
            self.selected = draft.boxes[0].box_id if draft.boxes else None
            self.frame = DraftFrame(sample, estimate_ground_z(sample.lidar), frozenset(ids))
            on_screen = self.on_screen()
        if not on_screen:
            self.back_to_draft_frame()
        self.refresh()

    def delete_selected_pair(self) -> None:
        """Delete the pair chosen in *Pair* (after a confirmation)."""
        sid = self._selected_pair()
        if sid is None:
            return
        self._confirm(
            f"Delete pair {sid}?",
            "The pair disappears from its split; its files and its history stay on disk.",
            "Delete the pair",
            lambda: self.delete_pair(sid),
        )

    def delete_pair(self, sample_id: str) -> None:
        """Delete a saved pair from the root."""
        store = self.store
        if store is None:
            return
        try:
            store.delete(sample_id, annotator=self.w.annotator.value)
        except (StoreError, OSError, ValueError) as exc:
            self.notify(f"Cannot delete pair {sample_id}", str(exc), color="red")
            return
        self.notify("Pair deleted", f"Pair {sample_id} was removed from its split.", color="green")
        self._after_store_change()

    def _confirm(self, title: str, text: str, action: str, fn: Callable[[], None]) -> None:
        """Ask in a modal window; ``fn`` runs when the person clicks ``action``."""
        gui = self.session.client.gui
        with gui.add_modal(title) as modal:
            gui.add_markdown(md_text(text))
            yes = gui.add_button(action, color="red")
            no = gui.add_button("Cancel")

        @yes.on_click
        def _(_: viser.GuiEvent) -> None:
            modal.close()
            self._guarded(fn)

        @no.on_click
        def _(_: viser.GuiEvent) -> None:
            modal.close()


def build_annotation_tab(session: ClientSession) -> AnnotationPanel:
    """Fill the Annotate tab of one browser (the extension point of :mod:`app.session`)."""
    shared = shared_root(session.app.frames.root.path)
    panel = AnnotationPanel(session, shared)
    session.add_frame_listener(panel.on_frame)
    session.add_answer_listener(panel.on_answer)
    return panel
