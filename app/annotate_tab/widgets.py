"""The widgets of the Annotate tab: built once per browser, in the tab's container.

:func:`build_annotation_widgets` adds them in the order a person uses them (status, *Pair
prompt*, *Save pair* with why it is disabled, *Draft*, placing and the *New box class*, the
*Boxes* folder (the selected box's editor with *Change class*, the ready-made boxes and the
evidence table), *Sentence*, *Save options*, *Saved pairs*) and returns their handles
(:class:`AnnotationWidgets`); what they do is wired by :mod:`app.annotate_tab.tab`.
"""

from __future__ import annotations

from dataclasses import dataclass

import viser

from annotate import DEFAULT_SPLITS
from app.annotate_tab.formatting import NO_BOX, NO_PAIRS, NO_READY
from scenes.geometry.classes import VOD

SPLITS = DEFAULT_SPLITS
"""Splits offered when saving (the store's default, ``train``, is selected); the store refuses any
other (a forged websocket message included)."""


@dataclass(frozen=True)
class AnnotationWidgets:
    """Handles of the Annotate tab (built by :func:`build_annotation_widgets`)."""

    status: viser.GuiMarkdownHandle
    back: viser.GuiButtonHandle
    prompt: viser.GuiTextHandle
    save: viser.GuiButtonHandle
    checks: viser.GuiMarkdownHandle
    draft: viser.GuiButtonGroupHandle
    place: viser.GuiCheckboxHandle
    cls: viser.GuiDropdownHandle
    box: viser.GuiDropdownHandle
    relabel: viser.GuiButtonGroupHandle
    length: viser.GuiNumberHandle
    width: viser.GuiNumberHandle
    height: viser.GuiNumberHandle
    yaw: viser.GuiNumberHandle
    fit: viser.GuiButtonHandle
    delete: viser.GuiButtonHandle
    ready: viser.GuiDropdownHandle
    add_ready: viser.GuiButtonHandle
    use_predictions: viser.GuiButtonHandle
    evidence: viser.GuiMarkdownHandle
    suggest: viser.GuiButtonHandle
    nothing: viser.GuiCheckboxHandle
    split: viser.GuiDropdownHandle
    annotator: viser.GuiTextHandle
    pair: viser.GuiDropdownHandle
    open_pair: viser.GuiButtonHandle
    delete_pair: viser.GuiButtonHandle
    pairs: viser.GuiMarkdownHandle
    selection: viser.GuiHtmlHandle
    """A hidden element saying whether a box is selected (:func:`selection_marker`)."""

    def box_inputs(self) -> tuple[viser.GuiInputHandle, ...]:
        """The inputs that edit the selected box (hidden while none is selected)."""
        return (
            self.relabel,
            self.length,
            self.width,
            self.height,
            self.yaw,
            self.fit,
            self.delete,
        )

    def ready_inputs(self) -> tuple[viser.GuiInputHandle, ...]:
        """The ready-made boxes' inputs (shown where the frame offers label_2 objects)."""
        return (self.ready, self.add_ready)


UNDO, REDO, NEW_PAIR = "Undo", "Redo", "New pair"
"""Buttons of the *Draft* group."""

PAIR_PROMPT = "Pair prompt"
"""The label of the sentence's field (the page-side key P finds the field by it)."""

NEW_BOX_CLASS, CHANGE_CLASS = "New box class", "Change class"
"""Labels of the two class controls: the next box's class, and the selected box's relabel."""

SELECTION_ATTRIBUTE = "data-talk2pc-box"
"""The attribute of the hidden element that tells the page whether a box is selected."""


def selection_marker(selected: bool) -> str:
    """The hidden element that tells the page whether a box is selected (``selected`` or
    ``none``): while one is, the keys that move it are not the 3D camera's too
    (:data:`app.annotate_tab.keys.KEY_OWNER_LISTENER`). Text of this module only."""
    return f'<span {SELECTION_ATTRIBUTE}="{"selected" if selected else "none"}" hidden></span>'


CLASS_KEYS = 9
"""Classes of a set with a key of their own: 1 to 9 (0 is *Refers to nothing*; Shift+digits type
other characters, which viser matches)."""


def class_key(index: int) -> str | None:
    """The key that sets *New box class* to class ``index`` (0-based) of the set: 1 to 9; None
    from the tenth class on (chosen from the dropdown; key C cycles a placed box through all)."""
    if index < 0:
        raise ValueError(f"class index must be >= 0, got {index}")
    return str(index + 1) if index < CLASS_KEYS else None


def build_annotation_widgets(
    gui: viser.GuiApi, classes: tuple[str, ...] = VOD.names
) -> AnnotationWidgets:
    """Add the Annotate tab's widgets to ``gui`` (in the current container).

    Order: what is used on every pair first, so that *Save pair* and the reason it is disabled
    are in sight without scrolling (1400 x 860 px): status, *Pair prompt*, *Save pair*, the
    checks, *Draft*, placing (*Click to place*, *New box class*), then the folders.

    Two controls, never one, for classes: *New box class* is the class of the next box placed
    and nothing else (choosing it never touches a placed box); *Change class* (shown while a box
    is selected) relabels the selected box, one undo step. Both offer exactly ``classes``: the
    served model's class set, in its order.
    """
    status = gui.add_markdown("Loading...")
    back = gui.add_button("Back to the draft's frame", icon=viser.Icon.ARROW_BACK, visible=False)
    prompt = gui.add_text(
        PAIR_PROMPT,
        "",
        multiline=True,
        hint="The sentence that refers to the boxes. Enter saves the pair when it is ready; "
        "Esc (or Tab) leaves the field",
    )
    save = gui.add_button("Save pair", color="green", icon=viser.Icon.DEVICE_FLOPPY, disabled=True)
    checks = gui.add_markdown("")
    draft = gui.add_button_group("Draft", (UNDO, REDO, NEW_PAIR))
    place = gui.add_checkbox(
        "Click to place",
        True,
        hint="A click on the ground places a box of the class below; a click on a draft box "
        "selects it; a click on a ready-made box adds it",
    )
    digits = ", ".join(k for i in range(len(classes)) if (k := class_key(i)) is not None)
    if len(classes) > CLASS_KEYS:
        digits += f" for the first {CLASS_KEYS}"
    cls = gui.add_dropdown(
        NEW_BOX_CLASS,
        classes,
        initial_value=classes[0],
        hint=f"The class of the next box a ground click places (keys {digits}). It never "
        "changes a placed box: Change class (Boxes) relabels the selected one",
    )
    with gui.add_folder("Boxes"):
        box = gui.add_dropdown("Box", (NO_BOX,), initial_value=NO_BOX)
        relabel = gui.add_button_group(
            CHANGE_CLASS,
            classes,
            visible=False,
            hint="Relabel the selected box (one undo step; key C cycles its class)",
        )
        size = {"min": 0.1, "max": 20.0, "step": 0.05, "visible": False}
        length = gui.add_number("Length (m)", 4.2, hint="Along the heading", **size)
        width = gui.add_number("Width (m)", 1.8, **size)
        height = gui.add_number("Height (m)", 1.5, hint="The bottom stays on the ground", **size)
        yaw = gui.add_number(
            "Yaw (deg)",
            0.0,
            min=-180.0,
            max=180.0,
            step=1.0,
            visible=False,
            hint="Counter-clockwise from forward (+x); the gizmo's ring turns it too",
        )
        fit = gui.add_button(
            "Fit to points",
            icon=viser.Icon.BOX_MODEL,
            visible=False,
            hint="Fit centre, size and yaw to the LiDAR points in and around the box",
        )
        delete = gui.add_button("Delete box", icon=viser.Icon.TRASH, visible=False)
        ready = gui.add_dropdown(
            "Object",
            (NO_READY,),
            initial_value=NO_READY,
            visible=False,
            hint="The frame's labelled objects (label_2) not in the draft yet",
        )
        add_ready = gui.add_button(
            "Add object",
            icon=viser.Icon.PLUS,
            visible=False,
            hint="Adds the chosen labelled object to the draft (a click on it in the 3D view "
            "does the same)",
        )
        use_predictions = gui.add_button(
            "Use predictions",
            icon=viser.Icon.WAND,
            disabled=True,
            hint="The boxes of the last answer (Query tab) become draft boxes",
        )
        evidence = gui.add_markdown("")
    with gui.add_folder("Sentence"):
        suggest = gui.add_button(
            "Suggest", icon=viser.Icon.BULB, hint="Write a Talk2Radar-style prompt for the boxes"
        )
        nothing = gui.add_checkbox(
            "Refers to nothing", False, hint="The prompt describes no object of this frame"
        )
    with gui.add_folder("Save options"):
        split = gui.add_dropdown("Split", SPLITS, initial_value=SPLITS[0])
        annotator = gui.add_text("Annotator", "", hint="Your name, recorded with the pair")
    with gui.add_folder("Saved pairs"):
        pair = gui.add_dropdown("Pair", (NO_PAIRS,), initial_value=NO_PAIRS)
        open_pair = gui.add_button("Open pair", icon=viser.Icon.FOLDER_OPEN, disabled=True)
        delete_pair = gui.add_button("Delete pair", icon=viser.Icon.TRASH, disabled=True)
        pairs = gui.add_markdown("")
    selection = gui.add_html(selection_marker(False))
    return AnnotationWidgets(
        status=status,
        back=back,
        prompt=prompt,
        save=save,
        checks=checks,
        draft=draft,
        place=place,
        cls=cls,
        box=box,
        relabel=relabel,
        length=length,
        width=width,
        height=height,
        yaw=yaw,
        fit=fit,
        delete=delete,
        ready=ready,
        add_ready=add_ready,
        use_predictions=use_predictions,
        evidence=evidence,
        suggest=suggest,
        nothing=nothing,
        split=split,
        annotator=annotator,
        pair=pair,
        open_pair=open_pair,
        delete_pair=delete_pair,
        pairs=pairs,
        selection=selection,
    )
