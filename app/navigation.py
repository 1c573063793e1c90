"""Scene navigation: the frames of one split of a Talk2Radar root, and the "Scene" controls.

Navigation is **shared** by every browser (the issue: "several browsers share the scene"): the app
holds one current frame, and previous / next / a frame number typed in any browser moves every
browser to that frame (each one's predictions are cleared and its prompt box gets the new
sample's own prompt). Query results, display settings and the camera stay per browser.

Frames are loaded on demand through :class:`FrameStore`, which keeps the last few in memory
(loading a synthetic frame reads three small files). Previous / next wrap around the split.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import viser

from app.scene_view import estimate_ground_z
from app.text import md_text
from scenes.root import RootError, Sample, Talk2RadarRoot


@dataclass(frozen=True)
class Frame:
    """One loaded frame of the split.

    Attributes:
        index: Position in the split (0-based).
        sample: The loaded sample (points in the LiDAR frame).
        ground_z: Ground height estimate (m, LiDAR frame).
    """

    index: int
    sample: Sample
    ground_z: float

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

    Raises:
        RootError: the split is missing or lists no frame.
    """

    def __init__(self, root: Talk2RadarRoot, split: str, cache_size: int = 4) -> None:
        self.root = root
        self.split = split
        self.ids: tuple[str, ...] = tuple(root.ids(split))
        if not self.ids:
            raise RootError(f"{root.path}: split {split!r} lists no frame")
        self.cache_size = max(1, cache_size)
        self._cache: OrderedDict[int, Frame] = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self.ids)

    def refresh(self) -> None:
        """Re-read the split's id list (e.g. after the annotation mode saved a sample) and drop
        the cached frames whose position changed."""
        ids = tuple(self.root.ids(self.split))
        if not ids:
            raise RootError(f"{self.root.path}: split {self.split!r} lists no frame")
        with self._lock:
            for index in list(self._cache):
                if index >= len(ids) or ids[index] != self.ids[index]:
                    del self._cache[index]
            self.ids = ids

    def index_of(self, sample_id: str) -> int:
        """Position of a sample id in the split (``ValueError`` when absent)."""
        return self.ids.index(sample_id)

    def load(self, index: int) -> Frame:
        """The frame at ``index`` (``0 <= index < len(self)``); errors name the file."""
        if not 0 <= index < len(self.ids):
            raise IndexError(f"frame {index} is out of range 0..{len(self.ids) - 1}")
        with self._lock:
            if index in self._cache:
                self._cache.move_to_end(index)
                return self._cache[index]
        sample = self.root.load(self.ids[index])
        frame = Frame(index=index, sample=sample, ground_z=estimate_ground_z(sample.lidar))
        with self._lock:
            self._cache[index] = frame
            while len(self._cache) > self.cache_size:
                self._cache.popitem(last=False)
        return frame


def frame_markdown(frame: Frame, count: int) -> str:
    """The frame summary shown under the navigation controls (the sample's text escaped)."""
    s = frame.sample
    gt = md_text(", ".join(s.classes)) if s.classes else "none"
    prompt = md_text(s.prompt) if s.prompt else "(this root has no prompts)"
    sid = (
        f"`{s.sample_id}`"
        if s.sample_id.isascii() and s.sample_id.isdigit()
        else md_text(s.sample_id)
    )
    return (
        f"**Frame {frame.index + 1} / {count}** · sample {sid}  \n"
        f"{len(s.lidar):,} LiDAR · {len(s.radar):,} radar points · GT: {gt}  \n"
        f"*Sample prompt:* {prompt}"
    )


@dataclass(frozen=True)
class NavigationPanel:
    """Handles of the "Scene" controls (built by :func:`build_navigation_panel`)."""

    step: viser.GuiButtonGroupHandle
    frame_number: viser.GuiNumberHandle
    info: viser.GuiMarkdownHandle


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
