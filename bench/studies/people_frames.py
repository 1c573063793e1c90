"""People's commands placed on synthetic frames (``python -m bench.people_commands``'s data).

A Talk2Car command file (the release's ``{"commands": [...]}``, each command with ``command``,
``obj_name`` and ``translation``, the referred object's centre in the CAM_FRONT frame: x right,
y down, z forward) is read into :class:`PeopleCommand`\\ s: the referred object's class in a class
set (nuScenes' detection mapping, :meth:`scenes.geometry.classes.ClassSet.category_class`; a
bicycle counts as ridden, so a three-class set takes cars, pedestrians and bicycles), its side of
the road (left / centre / right, :data:`SIDE_WIDTH` either side of the sensor's axis) and its
distance ahead. Commands about anything else (animals, debris, racks, a class outside the set)
are counted by category, never placed.

Each command is then placed on a synthetic frame where an object of its class is **the only one
of its class ahead**, on the same side and at a similar distance (:func:`similar`), so that the
class noun alone could find it: worlds of ``scenes.synth`` (the class set's road users, the
default rig, clear weather) are searched for such an actor, every other actor of that class ahead
(``x > 0``) is taken out of the world, and the world is sensed (:func:`scenes.synth.frame.sense_world`).
Commands share a frame when their class, side and distance bin (:data:`BIN_METRES`) agree;
``frames_per_bin`` frames per bin are made from different worlds and a command takes one by its
index. A referent that neither sensor sees is not a frame (the next world is tried).

Frames: LiDAR frame, x forward, y left, z up, metres (``shared/ARCHITECTURE.md``).
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from scenes.geometry.actors import Actor
from scenes.geometry.calib import sensor_to_lidar
from scenes.geometry.classes import WITH_RIDER, ClassSet
from scenes.synth.frame import (
    GENERATOR_VERSION,
    SynthFrame,
    SynthSettings,
    sense_world,
    world_streams,
)
from scenes.synth.world import World, generate_world
from scenes.utils.durable import atomic_write_text

SIDE_WIDTH = 1.5
"""Metres either side of the sensor's axis that count as "centre"; beyond: left or right."""
BIN_METRES = 5.0
"""Width of the distance bins commands share frames by."""
MAX_WORLDS = 1500
"""Worlds searched for one bin's frames before the bin's commands are counted as not placed."""


class CommandFileError(ValueError):
    """A command file that cannot be read (the message names the file and the command)."""


@dataclass(frozen=True)
class PeopleCommand:
    """One person's command and where its referred object was.

    Attributes:
        index: Position in the file's command list.
        text: The command as written.
        category: The referred object's nuScenes category (``obj_name``).
        cls: Its class in the class set, or None (not placed).
        side: ``left``, ``centre`` or ``right`` of the sensor's axis.
        distance: Metres ahead (CAM_FRONT z).
    """

    index: int
    text: str
    category: str
    cls: str | None
    side: str
    distance: float

    @property
    def bin_key(self) -> tuple[str, str, int]:
        """``(class, side, distance bin)``: commands with one key share frames."""
        return (self.cls or "", self.side, int(self.distance // BIN_METRES))


def side_of(lateral_left: float) -> str:
    """``left`` / ``centre`` / ``right`` of a lateral offset (metres, positive to the left)."""
    if lateral_left > SIDE_WIDTH:
        return "left"
    if lateral_left < -SIDE_WIDTH:
        return "right"
    return "centre"


def read_people_commands(path: Path, classes: ClassSet) -> tuple[list[PeopleCommand], Counter[str]]:
    """The commands of a Talk2Car command file, and the categories outside ``classes`` counted.

    Raises:
        CommandFileError: Not JSON, no ``commands`` list, or a command without a text, a category
            or a 3-number ``translation`` (named by its index).
    """
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CommandFileError(f"{path}: not a readable JSON command file ({exc})") from None
    raw = data.get("commands") if isinstance(data, dict) else None
    if not isinstance(raw, list):
        raise CommandFileError(f"{path}: no 'commands' list (a Talk2Car command file has one)")
    commands: list[PeopleCommand] = []
    outside: Counter[str] = Counter()
    for i, item in enumerate(raw):
        where = f"{path}: command {i}"
        if not isinstance(item, dict):
            raise CommandFileError(f"{where}: not an object")
        text, category, xyz = item.get("command"), item.get("obj_name"), item.get("translation")
        if not isinstance(text, str) or not text.strip():
            raise CommandFileError(f"{where}: field 'command' is not a non-empty text")
        if not isinstance(category, str):
            raise CommandFileError(f"{where}: field 'obj_name' is not a text")
        try:
            x, _, z = (float(v) for v in xyz)
        except (TypeError, ValueError):
            raise CommandFileError(f"{where}: field 'translation' is not 3 numbers") from None
        if not (math.isfinite(x) and math.isfinite(z)):
            raise CommandFileError(f"{where}: field 'translation' is not finite")
        cls = classes.category_class(category, (WITH_RIDER,))
        if cls is None:
            outside[category] += 1
        commands.append(PeopleCommand(i, text, category, cls, side_of(-x), z))
    return commands, outside


def similar(distance: float, target: float) -> bool:
    """Whether an actor ``distance`` metres ahead stands in for an object ``target`` metres
    ahead: within 2.5 m plus 10 % of the target."""
    return abs(distance - target) <= 2.5 + 0.1 * target


@dataclass(frozen=True)
class PlacedFrame:
    """A sensed frame whose referent is the only actor of its class ahead.

    Attributes:
        key: The bin it serves (:attr:`PeopleCommand.bin_key`).
        frame: The sensed world (LiDAR ``(N, 4)``, radar ``(M, 7)``, LiDAR frame).
        referent: The referent (its box ``(7,)`` in the LiDAR frame).
        classes: The class set's name the world was made for.
    """

    key: tuple[str, str, int]
    frame: SynthFrame
    referent: Actor
    classes: str = "vod"


class FramePlacer:
    """Finds and senses the frames of :mod:`bench.studies.people_frames` (module docstring)."""

    def __init__(
        self, classes: ClassSet, seed: int, frames_per_bin: int, cache: Path | None = None
    ) -> None:
        self.classes = classes
        self.settings = SynthSettings(seed=seed, camera=None, classes=classes.name)
        lidar_calib, radar_calib = self.settings.calibrations()
        self.radar_to_lidar = sensor_to_lidar(lidar_calib, radar_calib)
        self.frames_per_bin = frames_per_bin
        self._cache = cache
        self._index = self._read_index()
        self._used: set[int] = set()

    def _world(self, index: int) -> World:
        rng = world_streams(self.settings.seed, index)["world"]
        return generate_world(rng, index, self.settings.world)

    def _key(self) -> dict[str, object]:
        return {
            "generator": GENERATOR_VERSION,
            "classes": self.classes.name,
            "seed": self.settings.seed,
        }

    def _read_index(self) -> list[list[tuple[str, float, float]]]:
        """Every searched world's actors as ``(class, x, y)``: from the cache file when it was
        written for these worlds (generator version, class set, seed), else empty."""
        if self._cache is None or not self._cache.exists():
            return []
        try:
            data = json.loads(self._cache.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return []
        if not isinstance(data, dict) or data.get("key") != self._key():
            return []
        return [[(str(c), float(x), float(y)) for c, x, y in w] for w in data.get("worlds", [])]

    def save_index(self) -> None:
        """Write the worlds' index to the cache file (a later run searches without generating)."""
        if self._cache is not None:
            self._cache.parent.mkdir(parents=True, exist_ok=True)
            body = {"key": self._key(), "worlds": self._index}
            atomic_write_text(self._cache, json.dumps(body, separators=(",", ":")))

    def _actors_of(self, index: int) -> list[tuple[str, float, float]]:
        while len(self._index) <= index:
            world = self._world(len(self._index))
            self._index.append([(a.cls, float(a.box[0]), float(a.box[1])) for a in world.actors])
        return self._index[index]

    def _candidates(self, key: tuple[str, str, int]) -> Iterator[tuple[int, int]]:
        cls, side, dbin = key
        target = (dbin + 0.5) * BIN_METRES
        for index in range(MAX_WORLDS):
            for actor_id, (c, x, y) in enumerate(self._actors_of(index)):
                if c == cls and x > 0 and side_of(y) == side and similar(x, target):
                    yield index, actor_id

    def frames(self, key: tuple[str, str, int]) -> list[PlacedFrame]:
        """Up to ``frames_per_bin`` frames for ``key`` from distinct worlds (fewer where the
        worlds searched hold no such actor)."""
        out: list[PlacedFrame] = []
        for index, actor_id in self._candidates(key):
            if len(out) >= self.frames_per_bin:
                break
            if index in self._used:
                continue
            placed = self._place(key, index, actor_id)
            if placed is not None:
                self._used.add(index)
                out.append(placed)
        return out

    def _place(self, key: tuple[str, str, int], index: int, actor_id: int) -> PlacedFrame | None:
        world = self._world(index)
        cls = world.actors[actor_id].cls
        keep = [
            i
            for i, a in enumerate(world.actors)
            if i == actor_id or a.cls != cls or float(a.box[0]) <= 0
        ]
        actors = tuple(
            Actor(new, world.actors[old].cls, world.actors[old].box, world.actors[old].velocity)
            for new, old in enumerate(keep)
        )
        meshes = tuple(world.actor_meshes[old] for old in keep)
        edited = replace(world, actors=actors, actor_meshes=meshes)
        frame = sense_world(self.settings, edited, self.radar_to_lidar)
        new_id = keep.index(actor_id)
        if new_id not in frame.sensed:
            return None
        return PlacedFrame(key, frame, actors[new_id], self.classes.name)


def frame_of(command: PeopleCommand, frames: Sequence[PlacedFrame]) -> PlacedFrame | None:
    """The frame a command is grounded on: one of its bin's, by the command's index."""
    return frames[command.index % len(frames)] if frames else None


def bev_gap(boxes: np.ndarray, referent: Actor) -> np.ndarray:
    """``(K,)`` bird's-eye centre distances of ``(K, 7)`` boxes to the referent's centre."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    return np.hypot(boxes[:, 0] - referent.box[0], boxes[:, 1] - referent.box[1])
