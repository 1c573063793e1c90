"""Scene navigation: the frames of one split of a Talk2Radar root, and the "Scene" controls.

Navigation is **shared** by every browser (the issue: "several browsers share the scene"): the app
holds one current frame, and previous / next / a frame number typed in any browser moves every
browser to that frame (each one's predictions are cleared; the prompt box of the browser that
moved takes the new sample's own prompt unless its person typed there, the others' boxes are left
alone: :class:`app.query.panel.PromptField`). Query results, display settings and the camera stay per browser.

Frames are loaded on demand through :class:`FrameStore`, which keeps the last few in memory
(loading a synthetic frame reads three small files). Previous / next wrap around the split.

:class:`Navigator` holds the shared current frame. Browsers subscribe to it
(:class:`FrameSubscriber`: a new frame is shown, the split changed size); moving fails with a
:class:`NavigationError` (:class:`NoSuchFrameError`, :class:`FrameLoadError`) that the browser
which asked turns into a notification, so the navigator knows nothing of sessions or the GUI.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
import viser

from app.serving.frame_commands import FrameCommand, command_objects
from app.serving.ground_truth import NO_OBJECTS, FrameObjects, frame_objects
from app.text import md_text
from scenes.frame import FrameSource, RootError, Sample
from scenes.geometry.calib import LIDAR_HEIGHT
from scenes.geometry.ground import sensor_ground_height
from scenes.utils.lru import LRUCache

log = logging.getLogger(__name__)


def estimate_ground_z(lidar: np.ndarray, default: float = -LIDAR_HEIGHT) -> float:
    """Height of the ground (m, LiDAR frame) under the ego vehicle: the ground plane's height
    under the sensor (:func:`scenes.geometry.ground.sensor_ground_height`); ``default`` (the
    synthetic sensor's ground) when the cloud tells no plane.

    Args:
        lidar: ``(N, >=3)`` points, LiDAR frame.
    """
    pts = np.asarray(lidar, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 3:
        return float(default)
    return sensor_ground_height(pts, -float(default))


@dataclass(frozen=True)
class Frame:
    """One loaded frame of the split.

    Attributes:
        index: Position in the split (0-based).
        sample: The loaded sample (points in the LiDAR frame).
        ground_z: Ground height estimate (m, LiDAR frame).
        notes: Markdown lines under the frame summary (the root kind's
            :meth:`app.serving.served.ServedRoot.frame_notes`: a nuScenes sample's scene and commands).
        objects: Its labelled objects (the *Ground truth* layer, the answer's overlaps); on a
            frame with commands, the first command's referent is the referent
            (:func:`app.serving.frame_commands.command_objects`).
        commands: Its commands (:meth:`app.serving.served.ServedRoot.frame_commands`; None: the root
            kind has none, and the summary shows the sample's prompt instead).
    """

    index: int
    sample: Sample
    ground_z: float
    notes: str = ""
    objects: FrameObjects = NO_OBJECTS
    commands: tuple[FrameCommand, ...] | None = None

    @property
    def sample_id(self) -> str:
        return self.sample.sample_id


def step_index(index: int, delta: int, count: int) -> int:
    """``index + delta`` wrapped into ``[0, count)``."""
    if count <= 0:
        raise ValueError("step_index: the split is empty")
    return (index + delta) % count


class FrameStore:
    """The frames of ``split`` in ``root``, loaded on demand (thread-safe, small LRU cache).

    Args:
        root: The frames: a :class:`scenes.frame.FrameSource` (``ids``, ``load``, ``path``), the
            served root's reader of any family.
        split: The split served.
        cache_size: Frames kept.
        notes: The lines shown under a frame's summary (None: none).
        objects: A frame's labelled objects (:func:`app.serving.ground_truth.frame_objects`; the app
            gives it the root's full labels).
        commands: A frame's commands (None: the root kind has none).

    Raises:
        RootError: the split is missing or lists no frame.
    """

    def __init__(
        self,
        root: FrameSource,
        split: str,
        cache_size: int = 4,
        notes: Callable[[Sample], str] | None = None,
        objects: Callable[[Sample], FrameObjects] = frame_objects,
        commands: Callable[[Sample], tuple[FrameCommand, ...] | None] | None = None,
    ) -> None:
        self.root = root
        self._notes = notes
        self._objects = objects
        self._commands = commands
        self.split = split
        self.ids: tuple[str, ...] = tuple(root.ids(split))
        if not self.ids:
            raise RootError(f"{root.path}: split {split!r} lists no frame")
        self.cache_size = max(1, cache_size)
        self._cache: LRUCache[int, Frame] = LRUCache(self.cache_size)

    def __len__(self) -> int:
        return len(self.ids)

    def refresh(self) -> None:
        """Re-read the split's id list (e.g. after the annotation mode saved a sample) and drop
        the cached frames whose position changed."""
        ids = tuple(self.root.ids(self.split))
        if not ids:
            raise RootError(f"{self.root.path}: split {self.split!r} lists no frame")
        old = self.ids
        self._cache.discard_if(lambda index, _: index >= len(ids) or ids[index] != old[index])
        self.ids = ids

    def index_of(self, sample_id: str) -> int:
        """Position of a sample id in the split (``ValueError`` when absent)."""
        return self.ids.index(sample_id)

    def load(self, index: int) -> Frame:
        """The frame at ``index`` (``0 <= index < len(self)``); errors name the file."""
        if not 0 <= index < len(self.ids):
            raise IndexError(f"frame {index} is out of range 0..{len(self.ids) - 1}")
        cached = self._cache.get(index)
        if cached is not None:
            return cached
        sample = self.root.load(self.ids[index])
        notes = self._notes(sample) if self._notes is not None else ""
        ground_z = estimate_ground_z(sample.lidar)
        objects = self._objects(sample)
        commands = self._commands(sample) if self._commands is not None else None
        if commands is not None:  # the first command's referent, not every annotation
            objects = command_objects(objects, commands[0] if commands else None)
        frame = Frame(index, sample, ground_z, notes, objects, commands)
        self._cache.put(index, frame)
        return frame


class NavigationError(RuntimeError):
    """Moving to a frame failed; the current frame stays. ``title`` heads the notification."""

    title = "Navigation failed"


class NoSuchFrameError(NavigationError, IndexError):
    """The frame number is outside the split."""

    title = "No such frame"


class FrameLoadError(NavigationError):
    """The frame's files do not load (the cause is chained); ``title`` names the frame."""

    def __init__(self, title: str, cause: BaseException) -> None:
        super().__init__(f"{title}: {type(cause).__name__}: {cause}")
        self.title = title
        self.cause = cause


class FrameSubscriber(Protocol):
    """Something that shows the shared frame (a browser's session)."""

    def frame_shown(self, frame: Frame) -> None:
        """Draw ``frame``, the new current frame (called holding :attr:`Navigator.lock`)."""

    def split_changed(self) -> None:
        """The split was re-read (its size may differ); the current frame stays."""


class Navigator:
    """The current frame shared by every browser, and the split it belongs to.

    Args:
        frames: The split's frames.
        after_move: Called with the new frame after every move, outside the lock (the app
            starts encoding it for the modalities the browsers use).

    Every method is thread-safe; :attr:`lock` (reentrant) serialises moves, subscriptions and
    re-reads, so a subscriber sees frames in order and never misses one.
    """

    def __init__(
        self, frames: FrameStore, after_move: Callable[[Frame], None] | None = None
    ) -> None:
        self.frames = frames
        self.frame: Frame | None = None
        self.lock = threading.RLock()
        self._after_move = after_move
        self._subscribers: list[FrameSubscriber] = []

    def __len__(self) -> int:
        return len(self.frames)

    def load_first(self) -> Frame:
        """Make the first loadable frame of the split current (no subscriber is told).

        Raises:
            RootError: no frame of the split loads.
        """
        errors = []
        for index in range(len(self.frames)):
            try:
                frame = self.frames.load(index)
            except (RootError, OSError, ValueError) as exc:
                log.error("frame %d (%s) failed to load: %s", index, self.frames.ids[index], exc)
                errors.append(str(exc))
                continue
            with self.lock:
                self.frame = frame
            return frame
        raise RootError(f"no frame of split {self.frames.split!r} loads; first error: {errors[0]}")

    def subscribe(self, subscriber: FrameSubscriber) -> None:
        """Tell ``subscriber`` of every move and re-read from now on."""
        with self.lock:
            self._subscribers.append(subscriber)

    def unsubscribe(self, subscriber: FrameSubscriber) -> None:
        """Stop telling ``subscriber`` (no-op when it was not subscribed)."""
        with self.lock:
            self._subscribers = [s for s in self._subscribers if s is not subscriber]

    def go_to(self, index: int) -> Frame:
        """Make frame ``index`` (0-based) current and show it to every subscriber.

        Raises:
            NoSuchFrameError: ``index`` is outside the split.
            FrameLoadError: the frame does not load.
        """
        with self.lock:
            if not 0 <= index < len(self.frames):
                raise NoSuchFrameError(
                    f"There are frames 1..{len(self.frames)}; {index + 1} does not exist."
                )
            if self.frame is not None and index == self.frame.index:
                return self.frame
            try:
                frame = self.frames.load(index)
            except Exception as exc:
                title = f"Could not load frame {index + 1} ({self.frames.ids[index]})"
                raise FrameLoadError(title, exc) from exc
            self.frame = frame
            for subscriber in list(self._subscribers):
                try:
                    subscriber.frame_shown(frame)
                except Exception:  # one browser's failure must not stop the others
                    log.exception("a subscriber failed to show frame %d", index)
        if self._after_move is not None:
            self._after_move(frame)
        return frame

    def step(self, delta: int) -> Frame:
        """Go ``delta`` frames forward (negative: back), wrapping around the split (errors as
        :meth:`go_to`)."""
        with self.lock:
            current = self.frame.index if self.frame is not None else 0
            return self.go_to(step_index(current, delta, len(self.frames)))

    def reload(self) -> None:
        """Re-read the split (after samples were added to the root) and tell every subscriber;
        the frame on screen stays (its position may change)."""
        with self.lock:
            current = self.frame.sample_id if self.frame is not None else None
            self.frames.refresh()
            if current in self.frames.ids:
                index = self.frames.index_of(current)
                if self.frame is not None and index != self.frame.index:
                    self.frame = replace(self.frame, index=index)
            for subscriber in list(self._subscribers):
                subscriber.split_changed()


def frame_markdown(frame: Frame, count: int) -> str:
    """The frame summary shown under the navigation controls (the sample's text escaped); a
    frame of a root with commands lists them in its notes instead of a prompt line."""
    s = frame.sample
    gt = md_text(", ".join(s.classes)) if s.classes else "none"
    prompt = md_text(s.prompt) if s.prompt else "(this root has no prompts)"
    said = "" if frame.commands is not None else f"  \n*Sample prompt:* {prompt}"
    sid = (
        f"`{s.sample_id}`"
        if s.sample_id.isascii() and s.sample_id.isdigit()
        else md_text(s.sample_id)
    )
    return (
        f"**Frame {frame.index + 1} / {count}** · sample {sid}  \n"
        f"{len(s.lidar):,} LiDAR · {len(s.radar):,} radar points · GT: {gt}"
        + said
        + (f"  \n{frame.notes}" if frame.notes else "")
    )


@dataclass(frozen=True)
class NavigationPanel:
    """Handles of the "Scene" controls (built by :func:`build_navigation_panel`)."""

    step: viser.GuiButtonGroupHandle
    frame_number: viser.GuiNumberHandle
    info: viser.GuiMarkdownHandle

    def set_count(self, count: int) -> None:
        """The split has ``count`` frames (after a re-read)."""
        self.frame_number.max = count
        self.frame_number.hint = f"1..{count}"

    def show(self, frame: Frame, count: int) -> None:
        """Show ``frame`` (of ``count``) in the frame number box and the summary."""
        self.frame_number.value = frame.index + 1
        self.info.content = frame_markdown(frame, count)

    def wire(self, step: Callable[[int], object], go_to: Callable[[int], object]) -> None:
        """*Previous* / *Next* call ``step(-1)`` / ``step(1)``; a frame number typed in the
        browser calls ``go_to(number - 1)`` (a value set by the server calls nothing)."""

        @self.step.on_click
        def _(event: viser.GuiEvent) -> None:
            step(-1 if event.target.value == PREVIOUS else 1)

        @self.frame_number.on_update
        def _(event: viser.GuiEvent) -> None:
            if event.client is None:  # Set by the server (a frame shown), not typed.
                return
            value = self.frame_number.value
            if value is not None:
                go_to(int(round(value)) - 1)


PREVIOUS, NEXT = "Previous", "Next"
"""Labels of the step buttons."""


def build_navigation_panel(gui: viser.GuiApi, count: int) -> NavigationPanel:
    """Add the navigation widgets to ``gui`` (in the current container) for ``count`` frames."""
    step = gui.add_button_group("Frame", (PREVIOUS, NEXT))
    frame_number = gui.add_number(
        "Frame #", 1, min=1, max=max(count, 1), step=1, hint=f"1..{count}"
    )
    info = gui.add_markdown("Loading...")
    return NavigationPanel(step=step, frame_number=frame_number, info=info)
