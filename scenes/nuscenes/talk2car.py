"""Talk2Car command files: read strictly, paired with their nuScenes samples, and written in the
release's format.

``{split}_commands.json`` = ``{"scene_tokens": [...], "commands": [...]}``; a command refers to
one object: ``command`` (the sentence), ``obj_name`` (its nuScenes category), ``box_token`` (its
sample_annotation), ``translation`` / ``size`` (w, l, h) / ``rotation`` (w, x, y, z, four
*strings* in the release) in the CAM_FRONT camera frame (x right, y down, z forward),
``2d_box`` ``[x, y, w, h]`` whole pixels (integers in the release; read as any numbers,
written as integers: :func:`pixel_box`), ``sample_token`` (a **CAM_FRONT sample_data** token, not a
sample token), ``scene_token``, ``command_token``, ``t2c_img``.

:func:`read_commands` refuses a malformed file with one line naming the file, the command index
(and token) and the field; a well-formed command that cannot be used is counted by reason in
:attr:`CommandSet.skipped`, never dropped silently: a sample_token that is not a CAM_FRONT
key-frame sample_data, a scene_token other than the sample's, a box_token that is no
sample_annotation (or one of another sample), an ``obj_name`` other than the annotation's
category, a category outside the class set (:func:`scenes.nuscenes.classes.model_class`), and a
camera-frame box that disagrees with the annotation's by more than :data:`CENTRE_TOLERANCE` m or
:data:`YAW_TOLERANCE` rad.

A command's text goes through the one text policy, as a prompt does
(:func:`scenes.utils.text_policy.clean_text` under :data:`~scenes.utils.text_policy.COMMAND`):
a kept command's :attr:`Talk2CarCommand.text` is the normalised sentence, and one that the policy
refuses (a control, invisible or line-break character, even written as a JSON escape such as
``"\\u0000"``; more than 500 characters) is skipped and named in :attr:`CommandSet.skipped` by a
reason of its own, ``<file>: command <i> (<command_token>): <the policy's reason>``, so it is
never fed to the model, the app or training.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from scenes.geometry.boxes import wrap_yaw
from scenes.geometry.classes import VOD, ClassSet
from scenes.nuscenes.classes import model_class
from scenes.nuscenes.geometry import boxes_from_poses, quaternion_from_matrix, transform
from scenes.nuscenes.root import NuScenesError, NuScenesFrame, NuScenesRoot
from scenes.utils.durable import atomic_write_text
from scenes.utils.json_splice import splice_object
from scenes.utils.text_policy import COMMAND, TextPolicyError, clean_text
from scenes.utils.textfile import read_json_file

__all__ = [
    "CENTRE_TOLERANCE",
    "YAW_TOLERANCE",
    "CommandFileError",
    "CommandSet",
    "Referent",
    "Talk2CarCommand",
    "camera_box_to_model",
    "command_counts",
    "command_record",
    "commands_file",
    "model_box_to_camera",
    "pixel_box",
    "read_commands",
    "write_command_file",
    "write_commands",
]

CENTRE_TOLERANCE = 0.05
"""Metres: the most a command's camera-frame box centre may differ from its box_token's."""
YAW_TOLERANCE = float(np.radians(1.0))
"""Radians: the most a command's camera-frame heading may differ from its box_token's."""
FIELDS = (
    "scene_token", "sample_token", "translation", "size", "rotation", "command", "obj_name",
    "box_token", "command_token", "2d_box", "t2c_img",
)  # fmt: skip
"""The fields of a command, in the release's order."""


class CommandFileError(NuScenesError):
    """A Talk2Car command file is malformed; one line naming the file, command and field."""


def commands_file(folder: str | Path, split: str) -> Path:
    """``folder/{split}_commands.json``."""
    return Path(folder) / f"{split}_commands.json"


@dataclass(frozen=True)
class Talk2CarCommand:
    """One Talk2Car command as the file gives it.

    Attributes:
        command_token: The command's token.
        text: The sentence (``command``; once :func:`read_commands` kept it, normalised by the
            text policy).
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
        skipped: reason -> count of commands left out (a command refused by the text policy
            has a reason of its own naming the file, the command and why: count 1).
        scene_tokens: The file's ``scene_tokens``: the scenes of the split (Talk2Car splits by
            scene), with or without commands.
    """

    split: str
    commands: tuple[Talk2CarCommand, ...]
    referent: dict[str, Referent]
    skipped: Counter[str]
    scene_tokens: tuple[str, ...] = ()


def _numbers(value: object, n: int, *, strings: bool = False) -> np.ndarray | None:
    if not isinstance(value, list) or len(value) != n:
        return None
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float | str):
            return None
        if isinstance(v, str) and not strings:
            return None
        try:
            out.append(float(v))
        except ValueError:
            return None
    arr = np.asarray(out)
    return arr if np.isfinite(arr).all() else None


def _parse(path: Path, i: int, rec: object) -> Talk2CarCommand:
    """One command record, strictly."""
    if not isinstance(rec, dict):
        raise CommandFileError(f"{path}: command {i}: expected a JSON object")
    token = rec.get("command_token")
    where = f"{path}: command {i}" + (f" ({token})" if isinstance(token, str) else "")
    for name in FIELDS:
        if name not in rec:
            raise CommandFileError(f"{where}: field {name!r} is missing")
    for name in ("scene_token", "sample_token", "command", "obj_name", "box_token",
                 "command_token", "t2c_img"):  # fmt: skip
        if not isinstance(rec[name], str) or (name != "t2c_img" and not rec[name].strip()):
            raise CommandFileError(f"{where}: field {name!r}: expected a non-empty string")
    translation = _numbers(rec["translation"], 3)
    size = _numbers(rec["size"], 3)
    rotation = _numbers(rec["rotation"], 4, strings=True)
    box_2d = _numbers(rec["2d_box"], 4)
    checks = (
        ("translation", translation is not None, "3 numbers"),
        ("size", size is not None and bool((size > 0).all()), "3 positive numbers (w, l, h)"),
        ("rotation", rotation is not None and float(np.linalg.norm(rotation)) > 1e-9,
         "4 numbers or numeric strings (w, x, y, z), not all 0"),
        ("2d_box", box_2d is not None and bool((box_2d[2:] >= 0).all()),
         "4 numbers [x, y, w, h] with w, h >= 0"),
    )  # fmt: skip
    for name, ok, what in checks:
        if not ok:
            raise CommandFileError(f"{where}: field {name!r}: expected {what}")
    return Talk2CarCommand(
        command_token=rec["command_token"],
        text=rec["command"],
        scene_token=rec["scene_token"],
        sample_token="",
        cam_token=rec["sample_token"],
        box_token=rec["box_token"],
        category=rec["obj_name"],
        box_camera=(translation, size, rotation),
        box_2d=tuple(float(v) for v in box_2d),
        t2c_img=rec["t2c_img"],
    )


def command_counts(folder: str | Path, split: str) -> tuple[int, int]:
    """``(commands, samples)`` of ``folder/{split}_commands.json``: its commands, and how many
    samples they refer to (distinct ``sample_token`` values: CAM_FRONT keyframes, one per
    sample), read from the file alone, without the nuScenes root; commands that
    :func:`read_commands` would skip are counted too.

    Raises:
        CommandFileError: a missing file, or one without its ``commands`` list (one line).
    """
    _, data = _command_data(folder, split)
    commands = [c for c in data["commands"] if isinstance(c, dict)]
    return len(commands), len({c.get("sample_token") for c in commands})


def _command_data(folder: str | Path, split: str) -> tuple[Path, dict]:
    """``folder/{split}_commands.json`` and its JSON object, whose ``commands`` is a list.

    Raises:
        CommandFileError: a missing file, or one without its ``commands`` list (one line).
    """
    path = commands_file(folder, split)
    if not path.is_file():
        raise CommandFileError(f"{path}: no such Talk2Car command file")
    data = read_json_file(path, "Talk2Car command file", CommandFileError)
    if not isinstance(data, dict) or not isinstance(data.get("commands"), list):
        raise CommandFileError(f"{path}: field 'commands': expected a JSON object with a list")
    return path, data


def read_commands(
    folder: str | Path, split: str, root: NuScenesRoot, classes: ClassSet = VOD
) -> CommandSet:
    """Read ``folder/{split}_commands.json`` strictly and pair each command with its sample.

    Args:
        folder: The folder holding the command files (the full release: ``NUSC/commands``).
        split: ``train``, ``val``, ``test`` or any name a file carries.
        root: The nuScenes root the commands refer to.
        classes: The model's class set: a command whose referent's category maps outside it
            (:func:`scenes.nuscenes.classes.model_class`) is skipped; a kept referent's ``cls``
            is its class in this set.

    Returns:
        The kept commands (their :attr:`Talk2CarCommand.sample_token` resolved, their text
        normalised by the text policy), each one's referred annotation in the model frame, and
        the skipped ones by reason (a command the text policy refuses: one reason of its own
        naming the file, command and why).

    Raises:
        CommandFileError: a missing or malformed file (one line: file, command index, field), a
            command_token seen twice.
    """
    path, data = _command_data(folder, split)
    scenes = data.get("scene_tokens", [])
    if not isinstance(scenes, list) or not all(isinstance(s, str) for s in scenes):
        raise CommandFileError(f"{path}: field 'scene_tokens': expected a list of tokens")
    kept: list[Talk2CarCommand] = []
    referent: dict[str, Referent] = {}
    skipped: Counter[str] = Counter()
    seen: set[str] = set()
    anns = root.tables.records["sample_annotation"]
    geometry: dict[str, tuple] = {}
    for i, rec in enumerate(data["commands"]):
        cmd = _parse(path, i, rec)
        if cmd.command_token in seen:
            raise CommandFileError(
                f"{path}: command {i} ({cmd.command_token}): field 'command_token': seen before"
            )
        seen.add(cmd.command_token)
        try:
            cmd = replace(cmd, text=clean_text(cmd.text, COMMAND))
        except TextPolicyError as exc:
            skipped[f"{path}: command {i} ({cmd.command_token}): {exc}"] += 1
            continue
        try:
            sample = root.sample_of_camera(cmd.cam_token)
        except NuScenesError:
            skipped["sample_token is not a CAM_FRONT sample_data"] += 1
            continue
        if root.tables.records["sample"][sample]["scene_token"] != cmd.scene_token:
            skipped["scene_token is not the sample's scene"] += 1
            continue
        ann = anns.get(cmd.box_token)
        if ann is None:
            skipped["box_token not in sample_annotation"] += 1
            continue
        if ann["sample_token"] != sample:
            skipped["box_token is an annotation of another sample"] += 1
            continue
        if sample not in geometry:
            geometry[sample] = (*root.annotation_boxes(sample), root.to_camera(sample))
        boxes, categories, attributes, to_camera = geometry[sample]
        index = root.annotations(sample).index(cmd.box_token)
        if categories[index] != cmd.category:
            skipped["obj_name is not the annotation's category"] += 1
            continue
        cls = model_class(cmd.category, attributes[index], classes)
        if cls is None:
            skipped[f"category outside the class set: {cmd.category}"] += 1
            continue
        mine = camera_box_to_model(to_camera, *cmd.box_camera)
        box = boxes[index]
        if (
            np.linalg.norm(mine[:3] - box[:3]) > CENTRE_TOLERANCE
            or abs(wrap_yaw(mine[6] - box[6])) > YAW_TOLERANCE
        ):
            skipped["camera-frame box disagrees with box_token's annotation"] += 1
            continue
        kept.append(replace(cmd, sample_token=sample))
        referent[cmd.command_token] = Referent(box.copy(), cls, index)
    return CommandSet(split, tuple(kept), referent, skipped, tuple(scenes))


def pixel_box(box_2d: Sequence[float]) -> list[int]:
    """``[x, y, w, h]`` as the release writes ``2d_box``: the smallest box of whole pixels
    holding ``box_2d`` (its corners floored and ceiled; a box of whole pixels is kept)."""
    x, y, w, h = (float(v) for v in box_2d)
    left, top = math.floor(x + 1e-6), math.floor(y + 1e-6)
    right, bottom = math.ceil(x + w - 1e-6), math.ceil(y + h - 1e-6)
    return [left, top, max(right - left, 0), max(bottom - top, 0)]


def command_record(c: Talk2CarCommand) -> dict:
    """A command as the release's file writes it: its field names and order, ``sample_token`` =
    the CAM_FRONT sample_data token, ``rotation`` as four strings, ``2d_box`` as four integers
    (:func:`pixel_box`)."""
    translation, size, rotation = (np.asarray(v, dtype=np.float64) for v in c.box_camera)
    return {
        "scene_token": c.scene_token,
        "sample_token": c.cam_token,
        "translation": [float(v) for v in translation],
        "size": [float(v) for v in size],
        "rotation": [repr(float(v)) for v in rotation],
        "command": c.text,
        "obj_name": c.category,
        "box_token": c.box_token,
        "command_token": c.command_token,
        "2d_box": pixel_box(c.box_2d),
        "t2c_img": c.t2c_img,
    }


def write_command_file(
    path: str | Path, split: str, data: dict, previous: str | None = None
) -> Path:
    """Write the JSON object ``data`` (``scene_tokens``, ``commands`` and whatever else a file
    carries) as ``path/{split}_commands.json``, atomically. Returns the file written.

    ``previous``: the file's text as read (None: a new file). What ``data`` did not change keeps
    its bytes (:func:`scenes.utils.json_splice.splice_object`: every other key, every command
    kept, the file's layout; a byte-order mark too); else the whole object is written afresh."""
    out = commands_file(path, split)
    out.parent.mkdir(parents=True, exist_ok=True)
    text = None if previous is None else splice_object(previous.removeprefix("\ufeff"), data)
    if text is None:
        text = json.dumps(data, indent=1) + "\n"
    elif previous is not None and previous.startswith("\ufeff"):
        text = "\ufeff" + text
    atomic_write_text(out, text)
    return out


def write_commands(
    path: str | Path, split: str, scene_tokens: Sequence[str], commands: Sequence[Talk2CarCommand]
) -> Path:
    """Write ``path/{split}_commands.json`` (``path`` is the folder, as for
    :func:`read_commands`) in the release's format (:func:`command_record`), atomically.
    Returns the file written."""
    records = [command_record(c) for c in commands]
    return write_command_file(
        path, split, {"scene_tokens": list(scene_tokens), "commands": records}
    )


def _to_camera(frame: NuScenesFrame | np.ndarray) -> np.ndarray:
    return (
        frame.to_camera if isinstance(frame, NuScenesFrame) else np.asarray(frame, dtype=np.float64)
    )


def camera_box_to_model(
    frame: NuScenesFrame | np.ndarray,
    translation: np.ndarray,
    size_wlh: np.ndarray,
    rotation_wxyz: np.ndarray,
) -> np.ndarray:
    """A CAM_FRONT camera-frame box (Talk2Car's translation, size w l h, rotation w x y z) as a
    ``(7,)`` float64 model-frame box ``x, y, z, l, w, h, yaw``.

    Args:
        frame: The frame, or its ``to_camera`` ``(4, 4)`` (model -> camera).
    """
    model_from_camera = np.linalg.inv(_to_camera(frame))
    return boxes_from_poses(translation, size_wlh, rotation_wxyz, model_from_camera)[0]


def model_box_to_camera(
    frame: NuScenesFrame | np.ndarray, box: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ``(7,)`` model-frame box as ``(translation (3,), size_wlh (3,), rotation_wxyz (4,))``
    in the CAM_FRONT camera frame (Talk2Car's and the predictions file's form).

    Args:
        frame: The frame, or its ``to_camera`` ``(4, 4)`` (model -> camera).
    """
    to_camera = _to_camera(frame)
    box = np.asarray(box, dtype=np.float64).reshape(7)
    c, s = np.cos(box[6]), np.sin(box[6])
    heading = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    rotation = quaternion_from_matrix(to_camera[:3, :3] @ heading)
    return transform(box[:3], to_camera)[0], np.array([box[4], box[3], box[5]]), rotation
