"""Building one browser's Annotate tab: :func:`build_annotation_tab` wires the widgets, the scene
click, the gizmo and the hotkeys to the actions (:class:`~app.annotate_tab.edits.DraftEdits`,
:class:`~app.annotate_tab.pairs.PairActions`) and the panel to its session and hub.
"""

from __future__ import annotations

from collections.abc import Callable

import viser

from app.annotate_tab.edits import DraftEdits
from app.annotate_tab.hub import AnnotationHub
from app.annotate_tab.keys import (
    MOVE_FAR,
    MOVE_STEP,
    HelpWindow,
    add_help_folder,
    add_key_owner,
    add_prompt_key,
    keys_of,
    register_keys,
)
from app.annotate_tab.pairs import PairActions
from app.annotate_tab.panel import AnnotationPanel
from app.annotate_tab.referents import ReferentPicker
from app.annotate_tab.review import ReviewPanel
from app.annotate_tab.sequence import SequencePanel
from app.annotate_tab.widgets import NEW_PAIR, REDO, UNDO
from app.session import ClientSession


def build_annotation_tab(session: ClientSession, hub: AnnotationHub) -> AnnotationPanel:
    """Fill the Annotate tab of one browser (called inside the tab's container)."""
    panel = AnnotationPanel(session, hub)
    referents = ReferentPicker(panel)
    edits = DraftEdits(panel, referents)
    pairs = PairActions(panel)
    sequence = SequencePanel(panel)
    review = ReviewPanel(panel, pairs)
    _wire(panel, edits, pairs, referents)
    _register_keys(panel, edits, pairs, sequence, review)
    hub.register(panel)
    panel.refresh_pairs()
    panel.refresh()
    sequence.refresh()
    session.add_frame_listener(panel.on_frame)
    session.add_frame_listener(lambda _session: sequence.refresh())
    session.add_frame_listener(lambda _session: referents.prefetch())
    referents.prefetch()
    session.add_answer_listener(panel.on_answer)
    if session.query is not None:  # *Other annotations* shows or hides the ready-made boxes
        session.query.show_others.on_update(lambda _: panel.guarded(panel.refresh))
    return panel


def _from_browser(event: viser.GuiEvent) -> bool:
    """Whether a GUI event came from the browser (not from the server setting a value)."""
    return event.client is not None


def _wire(
    panel: AnnotationPanel, edits: DraftEdits, pairs: PairActions, referents: ReferentPicker
) -> None:
    w = panel.w
    scene = panel.session.client.scene

    @scene.on_click()
    def _(event: viser.SceneClickEvent) -> None:
        panel.guarded(lambda: edits.click_ground(event.ray_origin, event.ray_direction))

    @scene.on_click(modifier="shift")
    def _(event: viser.SceneClickEvent) -> None:
        panel.guarded(lambda: edits.place_box(event.ray_origin, event.ray_direction))

    panel.view.gizmo.on_update(edits.on_gizmo)

    def on_user(handle: viser.GuiInputHandle, fn: Callable[[], None]) -> None:
        def callback(event: viser.GuiEvent) -> None:
            if _from_browser(event):
                with panel.session.lock:  # reentrant; fn takes it too
                    # From here on no other callback can write the widget, and fn reads
                    # and applies this value: it is no longer a pending edit.
                    panel.accept_edit(handle)
                    panel.guarded(fn)

        handle.on_update(callback)

    def on_click(handle: viser.GuiButtonHandle, fn: Callable[[], None]) -> None:
        handle.on_click(lambda _event: panel.guarded(fn))

    on_user(w.box, edits.select_from_list)

    @w.relabel.on_click
    def _(event: viser.GuiEvent) -> None:
        cls = str(event.target.value)
        panel.guarded(lambda: edits.change_class(cls))

    @w.prompt.on_update
    def _(event: viser.GuiEvent) -> None:
        if not _from_browser(event):
            return
        with panel.session.lock:
            panel.accept_edit(w.prompt)
            entered = [False]
            panel.guarded(lambda: entered.__setitem__(0, edits.set_prompt()))
        if entered[0]:  # Enter: save outside the session's lock (the store's work), once the
            # referents shown were picked for this sentence (referents.ready_to_save)
            panel.guarded(lambda: referents.ready_to_save() and pairs.submit())

    for handle in (w.length, w.width, w.height):
        on_user(handle, lambda h=handle: edits.resize(h))
    on_user(w.yaw, edits.set_yaw)
    on_user(w.nothing, edits.set_nothing)
    on_click(w.fit, edits.fit_selected)
    on_click(w.delete, edits.delete_selected)
    on_click(w.use_predictions, edits.use_predictions)
    on_click(w.add_ready, edits.add_ready)
    on_click(w.suggest, edits.suggest)
    on_click(w.save, pairs.save)
    on_click(w.open_pair, pairs.open_selected_pair)
    on_click(w.delete_pair, pairs.delete_selected_pair)
    on_click(w.back, panel.back_to_draft_frame)

    @w.draft.on_click
    def _(event: viser.GuiEvent) -> None:
        action = {UNDO: edits.undo, REDO: edits.redo, NEW_PAIR: edits.new_pair}.get(
            event.target.value
        )
        if action is not None:
            panel.guarded(action)


def _register_keys(
    panel: AnnotationPanel,
    edits: DraftEdits,
    pairs: PairActions,
    sequence: SequencePanel,
    review: ReviewPanel,
) -> None:
    """The hotkeys of :data:`~app.annotate_tab.keys.KEYS`, the page-side key P and the help."""
    gui = panel.session.client.gui
    far, step = MOVE_FAR, MOVE_STEP
    actions: dict[str, Callable[[], None]] = {
        "add_ready": edits.add_ready,
        "use_predictions": edits.use_predictions,
        "select_next": lambda: edits.select_step(1),
        "select_previous": lambda: edits.select_step(-1),
        "deselect": edits.deselect,
        "class_next": lambda: edits.cycle_class(1),
        "class_previous": lambda: edits.cycle_class(-1),
        "move_forward": lambda: edits.move_on_screen(step, 0.0),
        "move_back": lambda: edits.move_on_screen(-step, 0.0),
        "move_left": lambda: edits.move_on_screen(0.0, -step),
        "move_right": lambda: edits.move_on_screen(0.0, step),
        "move_forward_far": lambda: edits.move_on_screen(far, 0.0),
        "move_back_far": lambda: edits.move_on_screen(-far, 0.0),
        "move_left_far": lambda: edits.move_on_screen(0.0, -far),
        "move_right_far": lambda: edits.move_on_screen(0.0, far),
        "turn_left": lambda: edits.turn(5.0),
        "turn_right": lambda: edits.turn(-5.0),
        "turn_left_fine": lambda: edits.turn(1.0),
        "turn_right_fine": lambda: edits.turn(-1.0),
        "turn_quarter": lambda: edits.turn(90.0),
        "turn_half": lambda: edits.turn(180.0),
        "fit": edits.fit_selected,
        "delete": edits.delete_selected,
        "suggest": edits.suggest,
        "referents": edits.pick_referents,
        "nothing": edits.toggle_nothing,
        "save": pairs.save,
        "undo": edits.undo,
        "redo": edits.redo,
        "new_pair": edits.new_pair,
        "help": HelpWindow(gui, keys=keys_of(panel.classes)).toggle,
        "play": sequence.toggle_play,
        "drive_previous": lambda: sequence.step(-1),
        "drive_next": lambda: sequence.step(1),
        "carry": sequence.carry,
        "review_next": lambda: review.step(1),
        "review_previous": lambda: review.step(-1),
        # approve, reject: the review panel's, bound to each pair shown (ReviewPanel.open)
        "fix": review.save_fix,
    }
    for i, cls in enumerate(panel.classes):
        actions[f"new_class_{i}"] = lambda cls=cls: edits.set_new_class(cls)
    keys = keys_of(panel.classes)
    register_keys(gui, actions, panel.guarded, keys)
    add_prompt_key(gui)
    add_key_owner(gui)
    add_help_folder(gui, keys=keys)
