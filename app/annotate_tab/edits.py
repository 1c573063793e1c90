"""What the person does to the draft in the Annotate tab: :class:`DraftEdits`.

Each action changes the panel's state through the :class:`annotate.DraftEditor` (one undo step)
and redraws only the :class:`~app.annotate_tab.panel.Part` s that show what it changed.

A click in the 3D view selects the draft box under it, else adds the ready-made box under it,
else places a new box of the *New box class*. In the sentence-first flow (the frame's boxes are
labelled: :mod:`app.annotate_tab.referents`) a click on nothing pickable places nothing and says
so: placing a box there is its own act, Shift+click (:meth:`DraftEdits.place_box`, also in the
other flow). A box that could not be saved where it would go
(outside the annotated range or the camera's view, :func:`annotate.validate`'s position and
image rules) is not placed or added, and a notification says why at once.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence

import numpy as np
import viser

from annotate import (
    BoxRegion,
    Draft,
    DraftError,
    FitError,
    SuggestConfig,
    default_box,
    fit_box,
    is_pristine,
    proposals,
    scene_objects,
    suggest_prompt,
)
from app.annotate_tab.formatting import option_index, option_ready_index, placement_problem
from app.annotate_tab.panel import AnnotationPanel, Part
from app.annotate_tab.referents import ReferentPicker
from app.annotate_tab.view import box_at, box_tag, ground_hit, screen_axes, wxyz_to_yaw
from app.query.prompt import submitted_prompt


class DraftEdits:
    """The draft-editing actions of one browser's tab (wired by :mod:`app.annotate_tab.tab`).

    Args:
        panel: The tab's state and drawing.
    """

    def __init__(self, panel: AnnotationPanel, referents: ReferentPicker) -> None:
        self.panel = panel
        self.referents = referents
        self._drag = 0
        """Gizmo drags so far: each drag is one undo step (its ``merge_key``)."""
        self._suggestions = 0
        """Suggestions so far: each one is drawn with a new seed."""

    # ------------------------------------------------------------------ scene interaction

    def _ground_point(
        self, ray_origin: Sequence[float], ray_direction: Sequence[float]
    ) -> tuple[float, float] | None:
        """Where a click's ray meets the draft's ground (None: no placing now, or no hit; every
        such click gets a notification saying why). Holds the session's lock."""
        p = self.panel
        if p.frame is None:
            p.notify("No frame yet", "The frame is still loading: click again once it is shown.")
            return None
        if not p.w.place.value:
            p.notify(
                "Click to place is off",
                "A click places, selects or adds no box while Click to place (Annotate tab) is "
                "off: tick it to go on, or select boxes with N / Shift+N.",
            )
            return None
        if not p.on_screen():
            p.notify(
                "The draft is on another frame",
                f"This draft belongs to sample {p.frame.name}. Go back to its frame "
                "(button in the Annotate tab) or start a new pair.",
            )
            return None
        hit = ground_hit(ray_origin, ray_direction, p.frame.ground_z)
        if hit is None:
            p.notify("Click on the ground", "That click did not hit the ground nearby.")
        return hit

    def place_box(self, ray_origin: Sequence[float], ray_direction: Sequence[float]) -> None:
        """Shift+click: place a new box of the *New box class* where the ray meets the ground,
        whatever is there (the explicit way to add a box the labels lack)."""
        p = self.panel
        with p.session.lock:
            hit = self._ground_point(ray_origin, ray_direction)
            if hit is None or p.frame is None:
                return
            if p.labelled() is not None:
                self.referents.by_hand()  # a box of one's own: the model no longer picks
            cls = p.w.cls.value
            self._add(default_box(cls, hit[0], hit[1], p.frame.ground_z), cls, "box")

    def click_ground(self, ray_origin: Sequence[float], ray_direction: Sequence[float]) -> None:
        """A click in the 3D view: select the draft box there (a labelled one in the pair:
        toggle it out), else add the ready-made box there, else place a new box, except in the
        sentence-first flow, where a click on nothing pickable only says so."""
        p = self.panel
        with p.session.lock:
            hit = self._ground_point(ray_origin, ray_direction)
            if hit is None or p.frame is None:
                return
            draft = p.editor.draft
            index = box_at(draft.box_array, *hit)
            labelled = p.labelled()
            if (
                index is not None
                and labelled is not None
                and labelled.index_of(draft.boxes[index].box) is not None
            ):  # a labelled box in the pair: a click toggles it out
                self.referents.by_hand()
                p.editor.delete_box(draft.boxes[index].box_id)
                p.refresh(Part.DRAFT)
                return
            if index is not None:
                p.selected = draft.boxes[index].box_id
                p.refresh(Part.SELECTION)
                return
            shown = p.offers_ready() and p.view.ready.visible  # (*Other annotations*)
            ready = box_at(p.ready_boxes, *hit) if shown else None
            if ready is not None:
                self.referents.by_hand()
                self._add(p.ready_boxes[ready], p.ready_classes[ready], "ready-made box")
                return
            if labelled is not None:  # sentence first: a near miss is not a new box
                p.notify(
                    "Nothing to pick there",
                    f"No labelled box at x = {hit[0]:.1f} m, y = {hit[1]:.1f} m: click on a "
                    "lavender box to add it, on a pair box to take it out. To place a new "
                    f"{p.w.cls.value} box there, Shift+click.",
                )
                return
            cls = p.w.cls.value
            self._add(default_box(cls, hit[0], hit[1], p.frame.ground_z), cls, "box")

    def _add(self, box: Sequence[float], cls: str, what: str) -> None:
        """Add a box to the draft and select it, unless it could not be saved where it is
        (then say why). Holds the session's lock."""
        p = self.panel
        assert p.frame is not None
        problems = p.placement_problems(box, cls)
        if problems:
            p.notify(f"No {what} placed there", placement_problem(problems) + ".")
            return
        p.selected = p.editor.add_box(box, cls)
        p.refresh(Part.DRAFT)

    def add_ready(self) -> None:
        """Add the ready-made box chosen in *Object* to the draft."""
        p = self.panel
        with p.session.lock:
            index = option_ready_index(p.w.ready.value)
            if p.frame is None or index is None or index >= len(p.ready_boxes):
                return
            self.referents.by_hand()
            self._add(p.ready_boxes[index], p.ready_classes[index], "ready-made box")

    async def on_gizmo(self, event: viser.TransformControlsEvent) -> None:
        """A gizmo drag (on the event loop, in message order): one undo step per drag."""
        p = self.panel
        box_id = p.view.gizmo_box_id
        if box_id is None:
            return
        if event.phase == "start":
            self._drag += 1
            return
        key = ("gizmo", box_id, self._drag)
        x, y, _ = (float(v) for v in event.target.position)
        yaw = wxyz_to_yaw(event.target.wxyz)
        try:
            p.editor.move_box(box_id, x, y, merge_key=key)
            p.editor.rotate_box(box_id, yaw, merge_key=key)
        except DraftError:  # The box went away (undo in another callback): drop the drag.
            return
        if event.phase == "end":  # Redraw in a worker thread; the loop goes on at once.
            asyncio.get_running_loop().run_in_executor(
                None, p.guarded, lambda: p.refresh(Part.DRAFT)
            )

    # ------------------------------------------------------------------ box edits

    def select_from_list(self) -> None:
        p = self.panel
        with p.session.lock:
            index = option_index(p.w.box.value)
            draft = p.editor.draft
            if index is None:
                p.selected = None
            elif index < len(draft.boxes):
                p.selected = draft.boxes[index].box_id
            p.refresh(Part.SELECTION)

    def change_class(self, cls: str) -> None:
        """*Change class*: relabel the selected box as ``cls`` (one undo step). The only way a
        placed box changes class; *New box class* never does."""
        p = self.panel
        if cls not in p.classes:  # a forged message
            return
        with p.session.lock:
            if p.selected is None:
                p.notify("No box selected", "Select a box first (click it, or keys N / Shift+N).")
                return
            if p.editor.draft.get(p.selected).cls != cls:
                p.editor.set_class(p.selected, cls)
                p.refresh(Part.DRAFT)

    def cycle_class(self, step: int = 1) -> None:
        """Relabel the selected box as the next (``step=1``) or previous class of
        the served model's class set (key C / Shift+C)."""
        p = self.panel
        with p.session.lock:
            if p.selected is None:
                p.notify("No box selected", "Select a box first (click it, or keys N / Shift+N).")
                return
            current = p.editor.draft.get(p.selected).cls
            classes = p.classes
            index = classes.index(current) if current in classes else -step
            self.change_class(classes[(index + step) % len(classes)])

    def set_new_class(self, cls: str) -> None:
        """*New box class* set from the keyboard (keys 1, 2, 3, ...); placed boxes keep theirs."""
        p = self.panel
        with p.session.lock:
            if cls in p.classes:
                p.w.cls.value = cls

    def select_step(self, step: int) -> None:
        """Select the next (``step=1``) or previous (``-1``) draft box in list order, wrapping
        around; with none selected, the first or the last (keys N / Shift+N)."""
        p = self.panel
        with p.session.lock:
            ids = p.editor.draft.box_ids
            if not ids:
                return
            if p.selected in ids:
                p.selected = ids[(ids.index(p.selected) + step) % len(ids)]
            else:
                p.selected = ids[0] if step > 0 else ids[-1]
            p.refresh(Part.SELECTION)

    def deselect(self) -> None:
        """Select no box (key Esc)."""
        p = self.panel
        with p.session.lock:
            if p.selected is not None:
                p.selected = None
                p.refresh(Part.SELECTION)

    def move_on_screen(self, forward: float, right: float) -> None:
        """Move the selected box ``forward`` m away from the viewer and ``right`` m to the right
        on screen, along the nearest LiDAR axes (:func:`~app.annotate_tab.view.screen_axes`;
        arrow keys). Consecutive moves of one box are one undo step."""
        p = self.panel
        with p.session.lock:
            if p.selected is None:
                return
            camera = p.session.client.camera
            (fx, fy), (rx, ry) = screen_axes(camera.position, camera.look_at)
            x, y = p.editor.draft.get(p.selected).box[:2]
            p.editor.move_box(
                p.selected,
                x + forward * fx + right * rx,
                y + forward * fy + right * ry,
                merge_key=("keys", "move", p.selected),
            )
            p.refresh(Part.DRAFT)

    def turn(self, degrees: float) -> None:
        """Turn the selected box by ``degrees`` counter-clockwise seen from above (keys Q, E,
        R); consecutive turns of one box are one undo step."""
        p = self.panel
        with p.session.lock:
            if p.selected is None:
                return
            yaw = p.editor.draft.get(p.selected).box[6] + float(np.radians(degrees))
            p.editor.rotate_box(p.selected, yaw, merge_key=("keys", "turn", p.selected))
            p.refresh(Part.DRAFT)

    def toggle_nothing(self) -> None:
        """Mark or unmark the prompt as referring to nothing (key 0)."""
        p = self.panel
        with p.session.lock:
            p.editor.set_refers_to_nothing(not p.editor.draft.refers_to_nothing)
            p.refresh(Part.TEXT)

    def resize(self, source: viser.GuiNumberHandle) -> None:
        p = self.panel
        with p.session.lock:
            if p.selected is not None:
                w = p.w
                p.editor.resize_box(
                    p.selected,
                    float(w.length.value),
                    float(w.width.value),
                    float(w.height.value),
                    merge_key=("size", p.selected),
                )
            p.refresh(Part.DRAFT, skip=source)

    def set_yaw(self) -> None:
        p = self.panel
        with p.session.lock:
            if p.selected is not None:
                yaw = float(np.radians(float(p.w.yaw.value)))
                p.editor.rotate_box(p.selected, yaw, merge_key=("yaw", p.selected))
            p.refresh(Part.DRAFT, skip=p.w.yaw)

    def set_prompt(self) -> bool:
        """*Pair prompt* changed; returns whether Enter was pressed (a line break in the value:
        the field is multi-line, see :mod:`app.query.panel`), which the line break's removal
        and the save follow (:meth:`app.annotate_tab.pairs.PairActions.submit`)."""
        p = self.panel
        with p.session.lock:
            value = p.w.prompt.value
            entered = submitted_prompt(value)
            if entered is not None:
                p.w.prompt.value = entered  # the browser's field loses the line break
                p.accept_edit(p.w.prompt)
            p.editor.set_prompt(entered if entered is not None else value)
            p.refresh(Part.TEXT, skip=p.w.prompt)
            if entered is None:
                self.referents.typed()
            return entered is not None

    def set_nothing(self) -> None:
        p = self.panel
        with p.session.lock:
            p.editor.set_refers_to_nothing(bool(p.w.nothing.value))
            p.refresh(Part.TEXT)

    def fit_selected(self) -> None:
        """Fit the selected box to the LiDAR points in and around it."""
        p = self.panel
        with p.session.lock:
            if p.selected is None or p.frame is None:
                return
            draft = p.editor.draft
            index = draft.index_of(p.selected)
            selected = draft.boxes[index]
            try:
                # The class's size prior completes an object seen from one side only.
                result = fit_box(p.frame.sample.lidar, BoxRegion(selected.box), cls=selected.cls)
            except (FitError, ValueError) as exc:
                p.notify("Cannot fit the box", str(exc))
                return
            p.editor.set_box(p.selected, result.box, label=f"fit {box_tag(index, '')}".strip())
            length, width, height = result.box[3:6]
            hidden = (
                f" The points show part of it; the box was completed to a {selected.cls}'s "
                "plausible size, away from the sensor."
                if result.completed
                else ""
            )
            p.notify(
                "Box fitted",
                f"{box_tag(index, selected.cls)} fitted to {result.num_points} LiDAR "
                f"points: {length:.2f} x {width:.2f} x {height:.2f} m.{hidden}",
                color="green",
            )
            p.refresh(Part.DRAFT)

    def delete_selected(self) -> None:
        """Delete the selected box (undoable)."""
        p = self.panel
        with p.session.lock:
            if p.selected is None:
                return
            self.referents.by_hand()
            p.editor.delete_box(p.selected)
            p.selected = None
            p.refresh(Part.DRAFT)

    def pick_referents(self) -> None:
        """Pick the sentence's referents among the frame's labelled boxes now (key L; *Use
        predictions* on a labelled frame), and let typing pick again."""
        p = self.panel
        if p.labelled() is None:
            p.notify("No labelled boxes", "This frame has no labelled boxes to pick among.")
            return
        if not p.editor.draft.prompt.strip():
            p.notify("Write the sentence first", "The referents are picked for the sentence.")
            return
        self.referents.auto = True
        count = self.referents.pick()
        if count is not None:
            p.notify("Referents picked", f"{count} labelled box(es) for the sentence.", "green")

    def use_predictions(self) -> None:
        """Add the last answer's boxes on this frame to the draft (one undo step); on a frame
        with labelled boxes, pick the sentence's referents among them instead."""
        p = self.panel
        if p.labelled() is not None:
            self.pick_referents()
            return
        with p.session.lock:
            answer = p.session.answer
            if answer is None:
                p.notify(
                    "No answer to use", "Run a prompt in the Query tab first; its boxes are added."
                )
                return
            if p.frame is None or answer.sample_id not in p.frame.sample_ids:
                p.notify(
                    "The answer is for another frame",
                    "Run the prompt again on the draft's frame.",
                )
                return
            pred = answer.predictions
            boxes, classes, duplicates = proposals(
                pred.boxes, pred.classes, p.editor.draft.box_array, allowed=p.classes
            )
            if not len(boxes):
                p.notify(
                    "No new boxes", "Every predicted box is already in the draft (or none fits)."
                )
                return
            ids = p.editor.add_boxes(boxes, classes)
            p.selected = ids[0]
            extra = f"; {duplicates} already in the draft" if duplicates else ""
            p.notify(
                "Predicted boxes added",
                f"{len(ids)} of {len(pred.boxes)} predicted box(es) added{extra}.",
                color="green",
            )
            p.refresh(Part.DRAFT)

    def suggest(self) -> None:
        """Write a suggested prompt for the boxes into *Pair prompt* (undoable)."""
        p = self.panel
        with p.session.lock:
            if p.frame is None:
                return
            draft = p.editor.draft
            self._suggestions += 1
            sample = p.frame.sample
            suggestion = suggest_prompt(
                draft.box_array,
                draft.classes,
                scene_objects(sample),
                sample.radar,
                np.random.default_rng(self._suggestions),
                SuggestConfig(classes=p.session.engine.classes),
            )
            if suggestion.text is None:
                p.notify("No suggestion", suggestion.reason or "no sentence fits these boxes")
                return
            p.editor.set_prompt(suggestion.text, merge_key=None)
            p.refresh(Part.TEXT)

    # ------------------------------------------------------------------ draft actions

    def undo(self) -> None:
        """Take back the last edit; the box it changed (if still there) becomes selected."""
        self._travel(self.panel.editor.undo)

    def redo(self) -> None:
        """Re-apply the last undone edit; the box it changed becomes selected."""
        self._travel(self.panel.editor.redo)

    def _travel(self, step: Callable[[], Draft]) -> None:
        p = self.panel
        with p.session.lock:
            before = p.editor.draft
            p.select_changed(before, step())
            p.refresh(Part.DRAFT)

    def new_pair(self) -> None:
        """Start a new pair on the frame on screen (asks first when there are unsaved edits)."""
        p = self.panel
        if p.editor.history.can_undo and not is_pristine(p.editor.draft):
            p.confirm(
                "Discard the draft?",
                "The draft has unsaved changes. Start a new pair and discard them?",
                "Discard the draft",
                self.reset_draft,
            )
        else:
            self.reset_draft()

    def reset_draft(self) -> None:
        """An empty draft on the frame on screen (no question asked)."""
        p = self.panel
        with p.session.lock:
            p.editor.reset()
            p.selected = None
            p.bind_to_screen()
            p.refresh()
