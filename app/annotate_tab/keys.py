"""The Annotate tab's keyboard: every step of a pair but the ground click has a key.

:data:`KEYS` is the one table of the tab's keys: :func:`register_keys` registers its hotkeys
(viser 1.1.1's experimental commands, ``gui.add_command``: they act while no text field has the
focus and are listed in its command palette, Ctrl/Cmd+K), and the help panel
(:func:`keys_markdown`, the *Keys* folder and the modal that key H opens) lists the same table,
so the two cannot disagree.

Two keys are the page's, not viser's (viser's client matches ``event.key``, and neither moving
the focus into a field nor a key typed in one is a hotkey): **P** puts the cursor in *Pair
prompt* (:data:`FOCUS_PROMPT_HTML`, installed once per page like :mod:`app.keys`'s Esc helper,
code of this module only) and **Enter** in *Pair prompt* saves (:mod:`app.annotate_tab.edits`);
**Esc** in a text field leaves it (:mod:`app.keys`).

Shifted digits are not used: viser matches the character a key types, and Shift+1 types ``!``.

**Keys belong to where the person is** (:data:`KEY_OWNER_LISTENER`, page-side, installed with
key P). viser's client runs a hotkey for every key that reaches the page's root element, unless
a text field has the focus; a focused slider (the Query tab's *Score threshold*, the drive's
frame slider), tab title or list kept its arrows *and* moved the draft's box. The listener
lets the focused control handle the key and stops it on ``document.body``, before the hotkeys,
when a slider, list or field has the focus (Esc also leaves a slider), when a tab title or a
button group's choice has it and the key is one they move with (arrows, Home, End, Space,
Enter), or when the Annotate tab is not the tab shown. **A key does one thing**: viser's client
also flies the 3D camera with the arrows, W / A / S / D and Q / E (:data:`CAMERA_KEYS`, heard on
``document``, after the hotkeys on the root element); while a box is selected (the hidden
element of :func:`app.annotate_tab.widgets.selection_marker` says so) a key a hotkey acted on
(it prevented the key's default) stops at the root element, so it moves the box and not the
camera; with no box selected the same keys fly the camera. The list of keys (H, :class:`HelpWindow`) is a floating
window, not a modal: it covers no click on the view; while it is open every key is its own (Esc
and H close it, the rest act on nothing behind it), and a click outside it closes it and goes
on to where it was aimed.
"""

from __future__ import annotations

import html
import logging
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import viser

from app.annotate_tab.widgets import PAIR_PROMPT, SELECTION_ATTRIBUTE, class_key
from app.text import md_text
from scenes.geometry.classes import VOD

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Key:
    """One key of the tab.

    Attributes:
        action: The name of the action it runs (a key of :func:`register_keys`'s ``actions``).
        key: viser's hotkey name (``"Z"``, ``"1"``, ``"arrowup"``, ``"delete"``); None for a
            key the page handles itself (listed only).
        modifier: viser's modifier (``"shift"``, ``"cmd/ctrl"``, ``"cmd/ctrl+shift"``) or None.
        label: The command palette's label.
        shown: How the help panel writes the key (``"Ctrl/Cmd+Shift+S"``).
        group: The help panel's section.
    """

    action: str
    key: str | None
    modifier: str | None
    label: str
    shown: str
    group: str


PLACE, BOXES, SENTENCE, PAIR = "Placing", "The selected box", "The sentence", "The pair"
SEQUENCE = "Sequences (splits with pose files)"
REVIEW = "Review"


def keys_of(classes: Sequence[str] = VOD.names) -> tuple[Key, ...]:
    """Every key of the Annotate tab for a model of ``classes``: a key per class of the set up
    to the ninth (:func:`app.annotate_tab.widgets.class_key`: 1, 2, 3, ... 9) sets *New box
    class*; a tenth class has no key (0 is *Refers to nothing*).

    Raises:
        ValueError: two actions on one key and modifier (a hotkey would run both).
    """
    out = [
        Key(f"new_class_{i}", key, None, f"New box class: {c}", key, PLACE)
        for i, c in enumerate(classes)
        if (key := class_key(i)) is not None
    ]
    out += [
        Key("add_ready", "A", None, "Add the chosen labelled object", "A", PLACE),
        Key("use_predictions", "U", None, "Use predictions (labelled frames: pick)", "U", PLACE),
        Key("select_next", "N", None, "Select the next box", "N", BOXES),
        Key("select_previous", "N", "shift", "Select the previous box", "Shift+N", BOXES),
        Key("deselect", "escape", None, "Select no box", "Esc", BOXES),
        Key("class_next", "C", None, "Change the box's class (next)", "C", BOXES),
        Key("class_previous", "C", "shift", "Change the box's class (previous)", "Shift+C", BOXES),
    ]
    for name, key in (("forward", "arrowup"), ("back", "arrowdown")):
        out.append(Key(f"move_{name}", key, None, f"Move the box {name} 0.1 m", "", BOXES))
        out.append(Key(f"move_{name}_far", key, "shift", f"Move the box {name} 1 m", "", BOXES))
    for name, key in (("left", "arrowleft"), ("right", "arrowright")):
        out.append(Key(f"move_{name}", key, None, f"Move the box {name} 0.1 m", "", BOXES))
        out.append(Key(f"move_{name}_far", key, "shift", f"Move the box {name} 1 m", "", BOXES))
    out += [
        Key("turn_left", "Q", None, "Turn the box 5 deg left", "Q", BOXES),
        Key("turn_right", "E", None, "Turn the box 5 deg right", "E", BOXES),
        Key("turn_left_fine", "Q", "shift", "Turn the box 1 deg left", "Shift+Q", BOXES),
        Key("turn_right_fine", "E", "shift", "Turn the box 1 deg right", "Shift+E", BOXES),
        Key("turn_quarter", "R", None, "Turn the box 90 deg", "R", BOXES),
        Key("turn_half", "R", "shift", "Turn the box 180 deg (flip its heading)", "Shift+R", BOXES),
        Key("fit", "F", None, "Fit the box to its points", "F", BOXES),
        Key("delete", "delete", None, "Delete the selected box", "Delete", BOXES),
        Key("delete", "backspace", None, "Delete the selected box", "Backspace", BOXES),
        Key("focus_prompt", None, None, "Write the sentence", "P", SENTENCE),
        Key("suggest", "G", None, "Suggest a sentence", "G", SENTENCE),
        Key("referents", "L", None, "Pick the referents among the labelled boxes", "L", SENTENCE),
        Key("nothing", "0", None, "Refers to nothing (toggle)", "0", SENTENCE),
        Key("save", "S", "cmd/ctrl+shift", "Save the pair", "Ctrl/Cmd+Shift+S", PAIR),
        Key("undo", "Z", "cmd/ctrl", "Undo", "Ctrl/Cmd+Z", PAIR),
        Key("redo", "Z", "cmd/ctrl+shift", "Redo", "Ctrl/Cmd+Shift+Z", PAIR),
        Key("new_pair", "delete", "shift", "New pair (discard the draft)", "Shift+Delete", PAIR),
        Key("help", "H", None, "Show the Annotate keys", "H", PAIR),
        Key("play", "space", None, "Play / pause the drive", "Space", SEQUENCE),
        Key("drive_previous", "pageup", None, "The drive's previous frame", "Page Up", SEQUENCE),
        Key("drive_next", "pagedown", None, "The drive's next frame", "Page Down", SEQUENCE),
        Key("carry", "T", None, "Carry the pair to the next frame", "T", SEQUENCE),
        Key("review_next", "J", None, "Review the next pair", "J", REVIEW),
        Key("review_previous", "K", None, "Review the previous pair", "K", REVIEW),
        Key("approve", "Y", None, "Approve the pair under review", "Y", REVIEW),
        Key("reject", "X", None, "Reject the pair under review", "X", REVIEW),
        Key("fix", "F", "shift", "Save the fix of the pair under review", "Shift+F", REVIEW),
    ]
    check_hotkeys(out)
    return tuple(out)


def check_hotkeys(keys: Sequence[Key]) -> None:
    """Raise ValueError when one hotkey (key and modifier, the key's case ignored) runs two
    actions: viser would run both on one press."""
    seen: dict[tuple[str, str | None], str] = {}
    for k in keys:
        if k.key is None:
            continue
        held = seen.setdefault((k.key.lower(), k.modifier), k.action)
        if held != k.action:
            mod = f"{k.modifier}+" if k.modifier else ""
            raise ValueError(f"key {mod}{k.key} would run both {held} and {k.action}")


KEYS: tuple[Key, ...] = keys_of()
"""Every key of the Annotate tab of a ``vod`` model (what :func:`register_keys` registers and the
help lists by default; :func:`keys_of` for another class set)."""

MOVE_STEP, MOVE_FAR = 0.1, 1.0
"""Metres one arrow key moves the selected box (with Shift: :data:`MOVE_FAR`)."""

TEXT_KEYS: tuple[tuple[str, str], ...] = (
    ("Enter (in Pair prompt)", "save the pair (when nothing blocks it)"),
    ("Esc (in a text field or a slider)", "leave it, so the next key is a hotkey"),
    ("Tab / Shift+Tab", "move through the controls (the sizes: Length, Width, Height, Yaw)"),
)
"""Keys that act inside text fields and controls (listed in the help; the browser's or the
page's, not hotkeys)."""


def keys_markdown(extra: tuple[Key, ...] = (), keys: tuple[Key, ...] = KEYS) -> str:
    """The help panel: every key of :data:`KEYS` (and ``extra``, e.g. a sequence player's) by
    section, then the keys that act in text fields."""
    rows: dict[str, list[tuple[str, str]]] = {}
    arrows = {
        "move_forward": "Up / Down / Left / Right",
        "move_forward_far": "Shift+arrows",
    }
    for k in (*keys, *extra):
        if k.action.startswith("move_") and k.action not in arrows:
            continue
        if k.action == "delete" and k.key == "backspace":
            continue
        shown, label = k.shown, k.label
        if k.action in arrows:
            shown = arrows[k.action]
            step = MOVE_STEP if k.action == "move_forward" else MOVE_FAR
            label = f"Move the box {step:g} m away / nearer / left / right on screen"
        elif k.action == "delete":
            shown = "Delete / Backspace"
        rows.setdefault(k.group, []).append((shown, label))
    lines = [
        "Hotkeys act in the Annotate tab while no text field, slider or list has the focus "
        "(Esc leaves one)."
    ]
    for group, items in rows.items():
        lines += ["", f"**{md_text(group)}**", "", "| key | action |", "| --- | --- |"]
        lines += [f"| {md_text(s)} | {md_text(label)} |" for s, label in items]
    lines += ["", "**In fields**", "", "| key | action |", "| --- | --- |"]
    lines += [f"| {md_text(s)} | {md_text(a)} |" for s, a in TEXT_KEYS]
    return "\n".join(lines)


def register_keys(
    gui: viser.GuiApi,
    actions: Mapping[str, Callable[[], None]],
    guarded: Callable[[Callable[[], None]], None],
    keys: tuple[Key, ...] = KEYS,
) -> int:
    """Register the hotkeys of ``keys`` whose action is in ``actions``; each runs its action
    through ``guarded`` (errors become notifications). Returns how many were registered (0 when
    this viser has no commands: the panel works without them)."""
    count = 0
    for k in keys:
        fn = actions.get(k.action)
        if k.key is None or fn is None:
            continue
        try:
            command = gui.add_command(k.label, hotkey=k.key, modifier=k.modifier)  # type: ignore[arg-type]
        except Exception as exc:  # Experimental in viser 1.1.1.
            log.warning("hotkey %s unavailable: %s", k.label, exc)
            return count
        command.on_trigger(lambda _event, fn=fn: guarded(fn))
        count += 1
    return count


FOCUS_PROMPT_LISTENER = (
    "if(!window.__talk2pcPromptKey){window.__talk2pcPromptKey=true;"
    "document.addEventListener('keydown',function(e){var t=e.target;"
    "if(String(e.key).toLowerCase()!=='p'||e.ctrlKey||e.metaKey||e.altKey||e.shiftKey)return;"
    "if(t&&(t.tagName==='TEXTAREA'||t.tagName==='INPUT'||t.tagName==='SELECT'"
    "||t.isContentEditable))return;"
    "var ls=document.querySelectorAll('label');for(var i=0;i<ls.length;i++){"
    f"if(ls[i].textContent!=='{PAIR_PROMPT}')continue;"
    "var row=ls[i].closest('.mantine-Flex-root');var a=row&&row.querySelector('textarea');"
    "if(a&&a.offsetParent!==null){e.preventDefault();a.focus();"
    "a.setSelectionRange(a.value.length,a.value.length);return;}}},true);}"
)
"""The page-side code of key P: focus the visible *Pair prompt* field (cursor at its end),
unless a text field has the focus (installed once per page)."""

FOCUS_PROMPT_HTML = (
    f'<img alt="" src="data:," style="display:none" onerror="{FOCUS_PROMPT_LISTENER}">'
)
"""The element that runs :data:`FOCUS_PROMPT_LISTENER` in the browser (see :mod:`app.keys`)."""


def add_prompt_key(gui: viser.GuiApi) -> viser.GuiHtmlHandle:
    """Make key P put the cursor in *Pair prompt* in this browser."""
    return gui.add_html(FOCUS_PROMPT_HTML)


def add_help_folder(
    gui: viser.GuiApi, extra: tuple[Key, ...] = (), keys: tuple[Key, ...] = KEYS
) -> viser.GuiFolderHandle:
    """The *Keys* folder (collapsed): :func:`keys_markdown`."""
    with gui.add_folder("Keys", expand_by_default=False) as folder:
        gui.add_markdown(keys_markdown(extra, keys))
    return folder


HELP_TITLE = "Annotate keys"
"""The title of the list of keys (the page-side listener finds the window by it)."""

HELP_CLOSE = "Close the key list"
"""Its close button's label (the page-side listener clicks it on Esc, H or a click outside)."""

CAMERA_KEYS = (
    *("KeyW", "KeyA", "KeyS", "KeyD", "KeyQ", "KeyE"),
    *("ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight"),
)
"""The keys (``KeyboardEvent.code``) that fly viser 1.1.1's 3D camera (its client listens on
``document``, after the hotkeys on the root element)."""

KEY_OWNER_LISTENER = (
    "if(!window.__talk2pcKeyOwner){window.__talk2pcKeyOwner=true;"
    f"var CLOSE='{HELP_CLOSE}',TITLE='{HELP_TITLE}';"
    "var OWN='input,textarea,select,[contenteditable=true],[role=slider],[role=combobox],"
    "[role=listbox],[role=option],[role=spinbutton],.mantine-Slider-root',NAVS='[role=tab],"
    "[role=radio]',NAV=['arrowleft','arrowright','arrowup','arrowdown','home','end',' ','enter'];"
    "function closer(){var bs=document.querySelectorAll('button');for(var i=0;i<bs.length;i++)"
    "{if(bs[i].textContent.trim()===CLOSE&&bs[i].offsetParent!==null)return bs[i];}return null;}"
    "function win(b){var n=b;while(n.parentElement&&n.textContent.indexOf(TITLE)<0)"
    "n=n.parentElement;return n;}"
    "function annotating(){var ts=document.querySelectorAll('[role=tab][aria-selected=true]');"
    "for(var i=0;i<ts.length;i++){if(ts[i].textContent.trim()==='Annotate')return true;}"
    "return false;}"
    "window.addEventListener('keydown',function(e){var b=closer();"
    "if(b){if(e.key==='Tab')return;e.preventDefault();e.stopImmediatePropagation();"
    "if(!e.repeat&&(e.key==='Escape'||String(e.key).toLowerCase()==='h'))b.click();return;}"
    "var k=String(e.key).toLowerCase();if((e.ctrlKey||e.metaKey)&&(k==='k'||k==='p'))return;"
    "var t=e.target,own=t&&t.closest?t.closest(OWN):null;"
    "if(!own&&t&&t.closest&&NAV.indexOf(k)>=0)own=t.closest(NAVS);"
    "if(own&&e.key==='Escape'&&own.closest('[role=slider],.mantine-Slider-root')&&t.blur)"
    "t.blur();"
    "if(own||!annotating())e.__talk2pcOwned=true;},true);"
    "document.body.addEventListener('keydown',function(e){"
    "if(e.__talk2pcOwned)e.stopPropagation();});"
    f"var CAMERA={list(CAMERA_KEYS)!r},MARK='{SELECTION_ATTRIBUTE}';"
    "function selected(){var m=document.querySelector('['+MARK+']');"
    "return !!m&&m.getAttribute(MARK)==='selected';}"
    "document.documentElement.addEventListener('keydown',function(e){"
    "if(e.defaultPrevented&&CAMERA.indexOf(e.code)>=0&&annotating()&&selected())"
    "e.stopPropagation();});"
    "window.addEventListener('pointerdown',function(e){var b=closer();if(!b)return;"
    "if(!win(b).contains(e.target))b.click();},true);}"
)
"""The page-side code that gives keys to where the person is (see the module docstring;
installed once per page)."""

KEY_OWNER_HTML = (
    f'<img alt="" src="data:," style="display:none" onerror="{html.escape(KEY_OWNER_LISTENER)}">'
)
"""The element that runs :data:`KEY_OWNER_LISTENER` in the browser (see :mod:`app.keys`; the
code escaped as an attribute value)."""


def add_key_owner(gui: viser.GuiApi) -> viser.GuiHtmlHandle:
    """Make the hotkeys act only where the person is, in this browser."""
    return gui.add_html(KEY_OWNER_HTML)


class HelpWindow:
    """The list of keys (key H) in a floating window of one browser (see the module docstring):
    :meth:`toggle` opens or closes it, its button closes it."""

    def __init__(
        self, gui: viser.GuiApi, extra: tuple[Key, ...] = (), keys: tuple[Key, ...] = KEYS
    ) -> None:
        self.gui = gui
        self.extra = extra
        self.keys = keys
        self.window: viser.PanelHandle | None = None
        self._lock = threading.Lock()

    def toggle(self) -> None:
        """Open the window, or close it when it is open."""
        with self._lock:
            if self.window is None:
                self._open()
                return
        self.close()

    def _open(self) -> None:
        window = self.gui.add_panel()
        with window.add_tab(HELP_TITLE, icon=viser.Icon.KEYBOARD):
            self.gui.add_markdown(keys_markdown(self.extra, self.keys))
            close = self.gui.add_button(HELP_CLOSE)
        close.on_click(lambda _event: self.close())
        window.float(x=16, y=16, width=460, height=460)  # top left: the view stays in sight
        self.window = window

    def close(self) -> None:
        """Close the window (nothing when it is closed)."""
        with self._lock:
            window, self.window = self.window, None
        if window is not None:
            window.remove()
