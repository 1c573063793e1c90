"""Talk2Car command files (skeleton: the contract's names; the reading lands next)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenes.nuscenes.root import NuScenesFrame, NuScenesRoot

__all__ = [
    "CommandSet",
    "Referent",
    "Talk2CarCommand",
    "camera_box_to_model",
    "model_box_to_camera",
    "read_commands",
    "write_commands",
]


@dataclass(frozen=True)
class Talk2CarCommand:
    """One Talk2Car command as the file gives it.

    Attributes:
        command_token: The command's token.
        text: The sentence (``command``).
        scene_token: The nuScenes scene.
        sample_token: The nuScenes SAMPLE token (resolved from :attr:`cam_token`).
        cam_token: The file's ``sample_token``: a CAM_FRONT sample_data token.
        box_token: The referred sample_annotation.
        category: ``obj_name``, a nuScenes category.
        box_camera: ``(translation (3,), size_wlh (3,), rotation_wxyz (4,))`` in the CAM_FRONT
            camera frame, as the file gives them.
        box_2d: ``(x, y, w, h)`` pixels.
        t2c_img: Talk2Car's image name.
    """

    command_token: str
    text: str
    scene_token: str
    sample_token: str
    cam_token: str
    box_token: str
    category: str
    box_camera: tuple[np.ndarray, np.ndarray, np.ndarray] = field(repr=False)
    box_2d: tuple[float, float, float, float]
    t2c_img: str


@dataclass(frozen=True)
class Referent:
    """The referred object of a kept command.

    Attributes:
        box: ``(7,)`` float64 model frame.
        cls: Its model class.
        index: Its index in the frame's annotations (``NuScenesFrame.annotation_tokens``).
    """

    box: np.ndarray = field(repr=False)
    cls: str
    index: int


@dataclass(frozen=True)
class CommandSet:
    """The commands of one split.

    Attributes:
        split: The split the file names.
        commands: The kept commands, in file order.
        referent: command_token -> its :class:`Referent`.
        skipped: reason -> count of commands left out.
    """

    split: str
    commands: tuple[Talk2CarCommand, ...]
    referent: dict[str, Referent]
    skipped: Counter[str]


def read_commands(folder: str | Path, split: str, root: NuScenesRoot) -> CommandSet:
    """Read ``folder/{split}_commands.json`` strictly and pair each command with its sample."""
    raise NotImplementedError


def write_commands(
    path: str | Path, split: str, scene_tokens: Sequence[str], commands: Sequence[Talk2CarCommand]
) -> None:
    """Write a command file in the release's format."""
    raise NotImplementedError


def camera_box_to_model(
    frame: NuScenesFrame, translation: np.ndarray, size_wlh: np.ndarray, rotation_wxyz: np.ndarray
) -> np.ndarray:
    """A CAM_FRONT camera-frame box as a ``(7,)`` model-frame box."""
    raise NotImplementedError


def model_box_to_camera(
    frame: NuScenesFrame, box: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ``(7,)`` model-frame box as ``(translation, size_wlh, rotation_wxyz)`` in CAM_FRONT."""
    raise NotImplementedError
