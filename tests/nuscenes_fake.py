"""A small stand-in for ``scenes.nuscenes`` (issue 40's contract: ``NuScenesRoot``,
``NuScenesFrame``, ``read_commands`` / ``CommandSet``, ``model_box_to_camera``, ``model_class``)
made from a synthetic Talk2Radar root, so that the model side's tests run before (and
independently of) the reader: :func:`install` puts it in ``sys.modules`` for one test.

Each synthetic sample becomes a nuScenes sample: its sidecar's actors are the annotations (plus
one ``vehicle.truck`` outside the class set, 8 m to the left), its prompt (when it has exactly one
referent) a Talk2Car command of its split with that referent; scene descriptions alternate
"Rain, ..." and "Night, ...".
"""

from __future__ import annotations

import sys
import types
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from scenes.geometry.calib import Calibration, boxes_2d, boxes_lidar_to_camera
from scenes.talk2radar.root import Talk2RadarRoot

CATEGORY = {
    "Car": "vehicle.car",
    "Pedestrian": "human.pedestrian.adult",
    "Cyclist": "vehicle.bicycle",
}
IMAGE_SIZE = (1600, 900)


def model_class(category: str, attributes) -> str | None:
    """The contract's mapping (today's three classes)."""
    if category == "vehicle.car":
        return "Car"
    if category.startswith("human.pedestrian.") and category.split(".")[-1] in (
        "adult",
        "child",
        "construction_worker",
        "police_officer",
    ):
        return "Pedestrian"
    if category == "vehicle.bicycle" and "cycle.with_rider" in attributes:
        return "Cyclist"
    return None


@dataclass(frozen=True)
class FakeFrame:
    sample_token: str
    scene_token: str
    cam_front_token: str
    lidar: np.ndarray
    lidar_time: np.ndarray
    radar: np.ndarray
    radar_time: np.ndarray
    boxes: np.ndarray
    categories: tuple[str, ...]
    attributes: tuple[tuple[str, ...], ...]
    annotation_tokens: tuple[str, ...]
    calib: Calibration
    to_camera: np.ndarray
    image_path: Path | None
    image_size: tuple[int, int]
    description: str


@dataclass(frozen=True)
class FakeCommand:
    command_token: str
    text: str
    scene_token: str
    sample_token: str
    cam_token: str
    box_token: str
    category: str
    box_camera: tuple
    box_2d: tuple[float, float, float, float]
    t2c_img: str


@dataclass
class FakeCommandSet:
    commands: tuple[FakeCommand, ...]
    referent: dict
    skipped: Counter = field(default_factory=Counter)
    split: str = "train"


REGISTRY: dict[str, tuple[dict[str, FakeFrame], dict[str, FakeCommandSet]]] = {}


class FakeRoot:
    def __init__(self, path, version=None, lidar_sweeps=1, radar_sweeps=1) -> None:
        self.path = Path(path)
        self.version = "v1.0-fake"
        self._frames, self._commands = REGISTRY[str(self.path.resolve())]
        self.samples = tuple(self._frames)

    def frame(self, token: str) -> FakeFrame:
        return self._frames[token]

    def scene_description(self, token: str) -> str:
        return self._frames[token].description


def read_commands(folder, split, root) -> FakeCommandSet:
    sets = REGISTRY[str(Path(root.path).resolve())][1]
    if split not in sets:
        raise FileNotFoundError(f"{Path(folder) / f'{split}_commands.json'}: no such file")
    return sets[split]


def model_box_to_camera(frame: FakeFrame, box: np.ndarray):
    """Centre into the camera frame; size w l h; yaw about the camera's y as a quaternion."""
    b = np.asarray(box, dtype=np.float64)
    centre = frame.to_camera @ np.r_[b[:3], 1.0]
    angle = -b[6] - np.pi / 2
    rotation = (np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0)
    return centre[:3].tolist(), [b[4], b[3], b[5]], list(rotation)


def make_fake(synth: Path, path: Path) -> Path:
    """A fake nuScenes root at ``path`` (a ``v1.0-fake`` folder in it) from a synthetic root."""
    (path / "v1.0-fake").mkdir(parents=True, exist_ok=True)
    (path / "commands").mkdir(exist_ok=True)
    source = Talk2RadarRoot(synth)
    frames: dict[str, FakeFrame] = {}
    sets: dict[str, FakeCommandSet] = {}
    seen: dict[tuple, str] = {}
    for split in ("train", "val", "test"):
        commands, referent = [], {}
        for sid in source.ids(split):
            sample = source.load(sid)
            key = source.frame_key(sid)
            if key not in seen:
                token = f"sample-{sid}"
                seen[key] = token
                actors = sample.meta.actors
                boxes = [a.box for a in actors] + [np.array([15.0, 8.0, -0.2, 8.0, 2.5, 3.0, 0.0])]
                cats = [CATEGORY[a.cls] for a in actors] + ["vehicle.truck"]
                attrs = [("cycle.with_rider",) if a.cls == "Cyclist" else () for a in actors]
                frames[token] = FakeFrame(
                    token,
                    f"scene-{sid}",
                    f"cam-{sid}",
                    np.asarray(sample.lidar, np.float32),
                    np.zeros(len(sample.lidar), np.float32),
                    np.asarray(sample.radar, np.float32),
                    np.zeros(len(sample.radar), np.float32),
                    np.array(boxes, dtype=np.float64).reshape(-1, 7),
                    tuple(cats),
                    (*tuple(attrs), ()),
                    tuple(f"ann-{sid}-{i}" for i in range(len(boxes))),
                    sample.calib,
                    sample.calib.velo_to_cam,
                    None,
                    IMAGE_SIZE,
                    ("Rain, " if len(frames) % 2 else "Night, ") + "busy street",
                )
            token = seen[key]
            frame = frames[token]
            if sample.prompt is None or len(sample.boxes) != 1:
                continue
            gaps = np.hypot(*(frame.boxes[:, :2] - sample.boxes[0, :2]).T)
            index = int(np.argmin(gaps))
            box = frame.boxes[index]
            x1, y1, x2, y2 = boxes_2d(
                boxes_lidar_to_camera(box[None], frame.calib), frame.calib, IMAGE_SIZE
            )[0]
            command = FakeCommand(
                f"cmd-{sid}",
                sample.prompt,
                frame.scene_token,
                token,
                frame.cam_front_token,
                frame.annotation_tokens[index],
                frame.categories[index],
                model_box_to_camera(frame, box),
                (x1, y1, x2 - x1, y2 - y1),
                f"img_{split}_{sid}.jpg",
            )
            commands.append(command)
            referent[command.command_token] = (box.copy(), sample.classes[0], index)
        sets[split] = FakeCommandSet(tuple(commands), referent, Counter(), split)
    REGISTRY[str(path.resolve())] = (frames, sets)
    return path


def install(monkeypatch: pytest.MonkeyPatch) -> None:
    """Put the stand-in modules in ``sys.modules`` for the test (restored after it)."""
    package = types.ModuleType("scenes.nuscenes")
    package.__path__ = []  # a package
    modules = {
        "scenes.nuscenes": package,
        "scenes.nuscenes.root": types.ModuleType("scenes.nuscenes.root"),
        "scenes.nuscenes.talk2car": types.ModuleType("scenes.nuscenes.talk2car"),
        "scenes.nuscenes.classes": types.ModuleType("scenes.nuscenes.classes"),
    }
    modules["scenes.nuscenes.root"].NuScenesRoot = FakeRoot
    modules["scenes.nuscenes.talk2car"].read_commands = read_commands
    modules["scenes.nuscenes.talk2car"].model_box_to_camera = model_box_to_camera
    modules["scenes.nuscenes.classes"].model_class = model_class
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)


__all__ = ["install", "make_fake", "model_class"]
