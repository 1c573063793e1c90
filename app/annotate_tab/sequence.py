"""Sequences in the Annotate tab: play a drive, and carry a pair to the next frame.

On a split whose frames come as drives (pose files, :mod:`scenes.talk2radar.drives`: View-of-Delft, or
``python -m scenes.synth --sequence-length N``), the *Sequence* folder shows where the frame on
screen is in its drive, a *Play* / *Pause* button (the drive plays at up to 10 Hz, as fast as the
frames draw, and stops at its last frame), the *Drive frame* slider and *Previous* / *Next*
(the drive's frames, skipping further prompts on the same frame), and **Carry to next frame**
(:meth:`SequencePanel.carry`).

Carrying: the current pair (the draft when it has boxes, else the pair this browser saved last,
when it was made on the frame on screen) becomes a new draft on the drive's next frame, its boxes
moved by the ego motion between the two frames' poses and by their radar ground velocities, and
refit where the radar could not tell the speed (:func:`annotate.carry.carry_boxes`, sensors only),
with the same sentence; the screen moves to that frame, and the annotator checks, edits and saves
it. Undo takes the carried boxes back (an empty draft on the new frame).

Keys (in :data:`app.annotate_tab.keys.KEYS`): Space plays / pauses, Page Up / Page Down step
through the drive, T carries.
Family specifics: a drive and the ego motion between two of its frames are the Talk2Radar
family's (:mod:`scenes.talk2radar.drives`, :mod:`scenes.talk2radar.poses`: View-of-Delft's ego
poses and frame rate; a nuScenes root's scenes come as the same drives), imported from that room.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass

import numpy as np
import viser

from annotate import Draft
from annotate.carry import carry_boxes
from app.annotate_tab.panel import AnnotationPanel, Part
from app.text import md_text
from scenes.talk2radar.drives import Drive, Drives
from scenes.talk2radar.poses import FRAME_RATE, lidar_motion

log = logging.getLogger(__name__)

PLAY, PAUSE = "Play", "Pause"
"""The labels of the play button."""
PREVIOUS, NEXT = "Previous", "Next"
"""The step buttons."""


@dataclass(frozen=True)
class SequenceWidgets:
    """The *Sequence* folder's handles."""

    folder: viser.GuiFolderHandle
    status: viser.GuiMarkdownHandle
    play: viser.GuiButtonHandle
    slider: viser.GuiSliderHandle
    step: viser.GuiButtonGroupHandle
    carry: viser.GuiButtonHandle


def build_sequence_widgets(gui: viser.GuiApi) -> SequenceWidgets:
    """The *Sequence* folder (hidden until the split has a drive of two frames or more)."""
    with gui.add_folder("Sequence", visible=False) as folder:
        status = gui.add_markdown("")
        play = gui.add_button(PLAY, icon=viser.Icon.PLAYER_PLAY, hint="Play the drive (Space)")
        slider = gui.add_slider(
            "Drive frame", min=1, max=2, step=1, initial_value=1, hint="Page Up / Page Down"
        )
        step = gui.add_button_group("Drive", (PREVIOUS, NEXT))
        carry = gui.add_button(
            "Carry to next frame",
            icon=viser.Icon.ARROW_FORWARD,
            hint="The pair's boxes on the drive's next frame, moved by the ego motion and "
            "their radar speed, refit to the points; check and save (T)",
        )
    return SequenceWidgets(folder, status, play, slider, step, carry)


class SequencePanel:
    """The *Sequence* folder of one browser's Annotate tab (see the module docstring).

    Args:
        panel: The tab's state and drawing.
    """

    def __init__(self, panel: AnnotationPanel) -> None:
        self.panel = panel
        self.w = build_sequence_widgets(panel.session.client.gui)
        self._playing = threading.Event()
        self._player: threading.Thread | None = None
        self._wire()

    # ------------------------------------------------------------------ where we are

    def drives(self) -> Drives:
        """The drives of the split served (the hub's, computed once per split list)."""
        frames = self.panel.navigator.frames
        return self.panel.hub.drives(frames.ids)

    def position(self) -> tuple[Drive, int] | None:
        """``(drive, frame index)`` of the frame on screen (None: no frame, or a lone frame)."""
        frame = self.panel.session.frame
        if frame is None:
            return None
        found = self.drives().find(frame.index)
        return found if found is not None and len(found[0]) > 1 else None

    def refresh(self) -> None:
        """The folder for the frame on screen (called holding the session's lock)."""
        w = self.w
        error = self.panel.hub.drives_error
        w.folder.visible = error is not None or self.drives().longest > 1
        found = self.position()
        if found is None:
            w.status.content = (
                f"**The drives cannot be read:** {md_text(error)}"
                if error is not None
                else "*The frame on screen is not part of a drive (no pose file).*"
            )
            w.play.disabled = w.slider.disabled = w.carry.disabled = True
            w.step.visible = False  # button groups cannot be disabled
            return
        drive, k = found
        w.status.content = f"Frame **{k + 1} / {len(drive)}** of this drive (10 Hz)."
        w.play.disabled = w.slider.disabled = False
        w.step.visible = True
        w.slider.max = len(drive)
        w.slider.value = k + 1
        w.carry.disabled = k + 1 >= len(drive)
        playing = self._playing.is_set()
        w.play.label = PAUSE if playing else PLAY
        w.play.icon = viser.Icon.PLAYER_PAUSE if playing else viser.Icon.PLAYER_PLAY

    # ------------------------------------------------------------------ moving

    def go_to_frame(self, k: int) -> bool:
        """Show frame ``k`` (0-based) of the drive on screen; False when there is none."""
        found = self.position()
        if found is None or not 0 <= k < len(found[0]):
            return False
        if k == found[1]:
            return True
        return self.panel.session.go_to(found[0].frames[k].first) is not None

    def step(self, delta: int) -> bool:
        """Show the drive's frame ``delta`` frames on (negative: back); False at its ends. A
        step by hand (a key, a button) pauses the drive first, so the player cannot step over it."""
        self.pause()
        return self._step(delta)

    def _step(self, delta: int) -> bool:
        found = self.position()
        return found is not None and self.go_to_frame(found[1] + delta)

    def pause(self) -> None:
        """Stop playing and wait for the player's last step (a no-op when not playing, or when
        called by the player itself)."""
        self._playing.clear()
        player = self._player
        if player is not None and player is not threading.current_thread():
            player.join(timeout=30.0)

    def toggle_play(self) -> None:
        """Play the drive from the frame on screen, or pause it (Space)."""
        if self._playing.is_set():
            self._playing.clear()
        else:
            found = self.position()
            if found is None:
                return
            if found[1] + 1 >= len(found[0]):  # at the end: play from the start
                self.go_to_frame(0)
            self._playing.set()
            self._player = threading.Thread(target=self._play, name="talk2pc-play", daemon=True)
            self._player.start()
        with self.panel.session.lock:
            self.refresh()

    def _play(self) -> None:
        period = 1.0 / FRAME_RATE
        try:
            while self._playing.is_set() and not self.panel.session.closed:
                start = time.monotonic()
                if not self._step(1):
                    break
                time.sleep(max(0.0, period - (time.monotonic() - start)))
        except Exception as exc:
            self.panel.session.report_error("Playing stopped", exc)
        finally:
            self._playing.clear()
            with self.panel.session.lock:
                if not self.panel.session.closed:
                    self.refresh()

    def stop(self) -> None:
        """Stop playing (the browser left)."""
        self._playing.clear()

    # ------------------------------------------------------------------ carrying

    def carry(self) -> None:
        """Carry the current pair to the drive's next frame (see the module docstring); asks
        first when the draft holds unsaved boxes (carrying leaves them unsaved on this frame)."""
        p = self.panel
        self.pause()
        with p.session.lock:
            draft = p.editor.draft
            unsaved = bool(draft.boxes) and p.on_screen() and p.editor.history.can_undo
        if unsaved:
            p.confirm(
                "Carry without saving?",
                "The pair on this frame is not saved. Carry its boxes to the next frame and "
                "leave it unsaved? (Save it first with Enter or Ctrl+Shift+S.)",
                "Carry without saving",
                self._carry,
            )
        else:
            self._carry()

    def _carry(self) -> None:
        p = self.panel
        with p.session.lock:
            found = self.position()
            draft, frame, sample = p.editor.draft, p.frame, p.session.sample
            source = None
            if draft.boxes and frame is not None and p.on_screen():
                source = (draft, frame)
            elif (
                p.last_pair is not None
                and sample is not None
                and sample.sample_id in p.last_pair[1].sample_ids
            ):
                source = p.last_pair
        if found is None or found[1] + 1 >= len(found[0]):
            p.notify("No next frame", "The frame on screen is the last of its drive.")
            return
        if source is None:
            p.notify(
                "Nothing to carry",
                "Make a pair on this frame first (its boxes are carried), or save one.",
            )
            return
        pair, pair_frame = source
        drive, k = found
        before, after = drive.frames[k].pose, drive.frames[k + 1].pose
        if before is None or after is None:  # a drive of two frames has both
            return
        shown = p.session.go_to(drive.frames[k + 1].first)
        if shown is None:
            return
        a, b = pair_frame.sample, shown.sample
        motion = lidar_motion(before, after, a.calib)
        carried = carry_boxes(
            pair.box_array, pair.classes, a.radar, motion, 1.0 / FRAME_RATE, b.lidar
        )
        boxes = np.array([c.box for c in carried]).reshape(-1, 7)
        with p.session.lock:
            p.editor.reset(Draft())
            p.bind_to_screen()
            ids = p.editor.add_boxes(boxes, pair.classes)
            p.editor.set_prompt(pair.prompt, merge_key=None)
            p.selected = ids[0] if ids else None
            p.refresh(Part.ALL)
        moved = sum(c.radar_points > 0 for c in carried)
        refit = sum(c.refit for c in carried)
        p.notify(
            f"Carried {len(carried)} box(es) to sample {b.sample_id}",
            f"All moved by the ego motion, {moved} by their radar speed too, {refit} refit "
            "to the points. Check them and the sentence, then save.",
            color="green",
        )

    # ------------------------------------------------------------------ wiring

    def _wire(self) -> None:
        w, p = self.w, self.panel
        w.play.on_click(lambda _e: p.guarded(self.toggle_play))
        w.carry.on_click(lambda _e: p.guarded(self.carry))

        @w.step.on_click
        def _(event: viser.GuiEvent) -> None:
            delta = -1 if event.target.value == PREVIOUS else 1
            p.guarded(lambda: self.step(delta))

        @w.slider.on_update
        def _(event: viser.GuiEvent) -> None:
            if event.client is None:  # set by the server (a frame shown)
                return
            k = int(round(float(w.slider.value))) - 1
            p.guarded(lambda: (self.pause(), self.go_to_frame(k)))
