"""A frame's commands, listed under the frame summary and run with a click: :class:`FrameCommand`,
:class:`CommandList`, and the referent of the command in play (:func:`command_objects`).

On a root whose samples carry commands (a nuScenes root with its Talk2Car commands:
:meth:`app.serving.served.ServedRoot.frame_commands`; a Talk2Radar root has one prompt per frame and
none), every frame lists its commands in the *Commands* folder under the frame summary, one button
each. A click on one runs it as if it had been typed into the Query tab's prompt box and run (the
box shows it; :meth:`app.session.ClientSession.run_command`) and makes it that browser's
**command in play**: its referred object is the frame's one referent, drawn apart from the other
annotations (thick, in :data:`app.view.colors.GT_COLOR`, labelled ``"#3 Car (referent)"``, in the 3D view
and the camera image), and the Query tab's *Other annotations* checkbox shows or hides all the
other annotations as one group. A new frame's command in play is its first (the one its prompt box
is offered); a prompt run that is one of the frame's commands becomes the one in play. The button
of the command in play is green.

A button's label is the command's text (plain text, never markup; long ones shortened with an
ellipsis, :data:`MAX_LABEL`), its hint the whole text and what it refers to.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import viser

from app.serving.ground_truth import FrameObjects, labelled_objects

__all__ = [
    "MAX_LABEL",
    "CommandList",
    "FrameCommand",
    "button_label",
    "command_in_play",
    "command_index",
    "command_objects",
]

MAX_LABEL = 72
"""Characters of a command shown on its button (the rest in its hint)."""


@dataclass(frozen=True)
class FrameCommand:
    """One command of a frame.

    Attributes:
        text: The sentence, as the prompt box runs it.
        box: ``(7,)`` its referred object, LiDAR frame.
        cls: The referred object's class (the served model's).
        about: Plain text on what it refers to (``"vehicle.car, 12.3 m ahead · train"``).
    """

    text: str
    box: np.ndarray = field(repr=False)
    cls: str
    about: str = ""


def command_index(commands: Sequence[FrameCommand] | None, text: str) -> int | None:
    """The first of ``commands`` whose text is ``text`` (None: none is)."""
    for i, c in enumerate(commands or ()):
        if c.text == text:
            return i
    return None


def command_in_play(
    commands: Sequence[FrameCommand] | None, current: int | None, text: str
) -> int | None:
    """The command in play once the prompt ``text`` is run: ``current`` when it is that text
    (or ``text`` is none of ``commands``), else the first command whose text it is."""
    if commands and current is not None and commands[current].text == text:
        return current
    found = command_index(commands, text)
    return current if found is None else found


def command_objects(objects: FrameObjects, command: FrameCommand | None) -> FrameObjects:
    """``objects`` with ``command``'s referred object as the one referent (matched by 3D IoU,
    added when no object matches: :func:`app.serving.ground_truth.labelled_objects`); no referent for
    None."""
    refs = np.zeros((0, 7)) if command is None else np.asarray(command.box).reshape(1, 7)
    classes = () if command is None else (command.cls,)
    return labelled_objects(objects.boxes, objects.classes, refs, classes, objects.source)


def button_label(index: int, text: str) -> str:
    """A command's button: ``"2. turn left after the bus"`` (shortened past :data:`MAX_LABEL`)."""
    shown = text if len(text) <= MAX_LABEL else text[: MAX_LABEL - 1].rstrip() + "…"
    return f"{index + 1}. {shown}"


class CommandList:
    """One browser's *Commands* folder (added to the GUI container current when built).

    Args:
        gui: The browser's GUI API.
        run: Called with a command's index when its button is clicked.
    """

    def __init__(self, gui: viser.GuiApi, run: Callable[[int], object]) -> None:
        self.gui = gui
        self._run = run
        self.folder = gui.add_folder("Commands")
        with self.folder:
            self.note = gui.add_markdown("")
        self.folder.visible = False
        self.buttons: list[viser.GuiButtonHandle] = []

    def show(self, commands: Sequence[FrameCommand] | None, current: int | None) -> None:
        """List ``commands`` (None or none: the folder is hidden), ``current`` marked."""
        for button in self.buttons:
            button.remove()
        self.buttons = []
        self.folder.visible = bool(commands)
        if not commands:
            return
        self.note.content = (
            f"*{len(commands)} command{'s' if len(commands) != 1 else ''} of this sample: a click "
            "runs one; its referent is drawn thick and green*"
        )
        with self.folder:
            for i, c in enumerate(commands):
                button = self.gui.add_button(
                    button_label(i, c.text),
                    icon=viser.Icon.PLAYER_PLAY,
                    hint=f"{c.text} → {c.cls}" + (f" ({c.about})" if c.about else ""),
                )
                button.on_click(lambda _, index=i: self._run(index))
                self.buttons.append(button)
        self.mark(current)

    def mark(self, current: int | None) -> None:
        """Colour the button of the command in play (``current``) green, the others plain."""
        for i, button in enumerate(self.buttons):
            button.color = "green" if i == current else None
