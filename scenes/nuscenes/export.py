"""Synthetic frames written as nuScenes and Talk2Car come (:func:`export_frames`), for tests and
docs; ``python -m scenes.export_nuscenes`` feeds it a synthetic root.

A :class:`SourceFrame` is one synthetic frame in the model frame (LiDAR (N, 4), radar (M, 7)
with ``time = -k`` scans, every actor, the camera); frames of one world become one nuScenes scene,
each frame one sample, each single-referent prompt one Talk2Car command. Per sample:

- a random global pose (yaw, position) of the ego at the LIDAR_TOP key frame's time; every other
  sample_data has its own timestamp (CAM_FRONT 5 ms later, the radars 8 to 40 ms later, older radar
  sweeps ``k`` scan periods earlier) and its own ego pose, the ego moving along its x at the
  frame's speed. The sensor files are written so that the chain sensor -> ego(t) -> global brings
  each point back to where the source has it at the key frame.
- LIDAR_TOP at ``[0.943713, 0, 1.84023]`` in the ego frame, rotated -90 degrees about z (x right,
  y forward: ``[0.7071, 0, 0, -0.7071]``); its file ``x, y, z, intensity, ring`` with the ring index
  from the elevation (:func:`ring_index`, 64 beams from +2 to -24.9 degrees, 0 the top one).
- the five radars at nuScenes-like mounts (:data:`RADAR_MOUNTS`); each radar point goes to the
  radar whose boresight is closest to its azimuth, with its radial speeds resolved along that
  radar's line of sight (:func:`scenes.nuscenes.radar.radial_components`); an empty sweep is
  one NaN point.
- CAM_FRONT: the source's camera image resized and padded to 1600 x 900 (intrinsics scaled and
  shifted to match) or a grey image where the source has none; its extrinsics are the source
  camera's, so boxes project on the image as in the source.
- every actor a sample_annotation (global box, size w l h, its class's category
  (:data:`scenes.nuscenes.classes.CLASS_CATEGORY`) and attribute, moving or still, by nuScenes'
  conventions (:attr:`scenes.geometry.classes.ObjectClass.attributes`; none for cones and
  barriers), num_lidar_pts / num_radar_pts counted), one instance per actor of a world; actors
  of every class set's classes are written.
- a command's camera-frame box at the camera's own time (as Talk2Car gives them) and its 2D box
  projected and clipped to the image; a prompt whose referent is not wholly in front of the camera
  is skipped and counted.
"""

from __future__ import annotations

import io
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image

from scenes.geometry.actors import Actor
from scenes.geometry.boxes import box_corners, points_in_boxes
from scenes.geometry.calib import Calibration
from scenes.geometry.classes import object_class
from scenes.nuscenes.classes import CLASS_CATEGORY
from scenes.nuscenes.geometry import (
    MODEL_TO_LIDAR,
    pose_matrix,
    quaternion_from_matrix,
    quaternion_from_yaw,
    transform,
)
from scenes.nuscenes.radar import RADAR_CHANNELS, radial_components
from scenes.nuscenes.sensorfiles import write_lidar, write_radar
from scenes.nuscenes.talk2car import Talk2CarCommand, model_box_to_camera, write_commands
from scenes.nuscenes.writer import TableWriter, token
from scenes.utils.durable import atomic_write_bytes

Sentence = Callable[[str, Actor, tuple[int, ...]], str]
"""A command's sentence from a prompt's text, its referent and a key to draw from."""

__all__ = [
    "IMAGE_SIZE",
    "LIDAR_MOUNT",
    "RADAR_MOUNTS",
    "ExportReport",
    "SourceFrame",
    "SourcePrompt",
    "export_frames",
    "ring_index",
]

IMAGE_SIZE = (1600, 900)
"""CAM_FRONT's image size (width, height)."""
LIDAR_MOUNT = ((0.943713, 0.0, 1.84023), (float(np.sqrt(0.5)), 0.0, 0.0, -float(np.sqrt(0.5))))
"""LIDAR_TOP's calibrated translation and rotation (w, x, y, z) in the ego frame."""
RADAR_MOUNTS: dict[str, tuple[tuple[float, float, float], float, int]] = {
    "RADAR_FRONT": ((3.412, 0.0, 0.5), 0.0, 8000),
    "RADAR_FRONT_LEFT": ((2.422, 0.8, 0.78), np.radians(88.0), 16000),
    "RADAR_FRONT_RIGHT": ((2.409, -0.8, 0.7), np.radians(-89.0), 24000),
    "RADAR_BACK_LEFT": ((-0.562, 0.628, 0.53), np.radians(176.0), 32000),
    "RADAR_BACK_RIGHT": ((-0.566, -0.614, 0.53), np.radians(-178.0), 40000),
}
"""Radar -> (translation in the ego frame, yaw of its boresight, its time after LIDAR_TOP in µs)."""
CAMERA_DELAY_US = 5000
"""CAM_FRONT's time after the LIDAR_TOP key frame (µs)."""
SAMPLE_PERIOD_US = 500_000
"""Time between the samples of a scene (nuScenes' key frames come at 2 Hz)."""
BEAMS = (2.0, -24.9, 64)
"""The ring layout :func:`ring_index` assumes: top and bottom elevation (degrees), beams."""


@dataclass(frozen=True)
class SourcePrompt:
    """One prompt of a source frame: its sample id, split, sentence and referred actor ids."""

    sample_id: str
    split: str
    text: str
    referent_ids: tuple[int, ...]


@dataclass(frozen=True)
class SourceFrame:
    """One synthetic frame to export.

    Attributes:
        world: The world it belongs to (one nuScenes scene per world).
        lidar: ``(N, 4)`` float32 model frame.
        radar: ``(M, 7)`` float32 model frame, ``time`` = ``-k`` for the k-th older scan.
        actors: Every actor of the frame.
        calib: Model frame -> camera (``Tr_velo_to_cam``) and the intrinsics (``P2``).
        image_path: The camera image, or None.
        image_size: ``(width, height)`` of the source camera.
        weather: ``clear``, ``rain`` or ``fog``.
        ego_speed: m/s along +x.
        prompts: Its prompts.
    """

    world: int
    lidar: np.ndarray = field(repr=False)
    radar: np.ndarray = field(repr=False)
    actors: tuple[Actor, ...]
    calib: Calibration = field(repr=False)
    image_path: Path | None
    image_size: tuple[int, int]
    weather: str
    ego_speed: float
    prompts: tuple[SourcePrompt, ...]


@dataclass(frozen=True)
class ExportReport:
    """What :func:`export_frames` wrote: scenes, samples, commands per split, skipped prompts
    by reason."""

    scenes: int
    samples: int
    commands: dict[str, int]
    skipped: Counter[str]
    """Prompts left out, by reason (a phrase that follows their count: "with 2 referents")."""

    def summary(self) -> str:
        """What was written, as sentences: ``"3 scenes, 12 samples; commands: 6 in train and 2
        in val. 16 prompts were left out (a Talk2Car command refers to exactly one object, in
        front of CAM_FRONT): 14 with 2 referents and 2 with 4 referents."``"""
        commands = _and([f"{n} in {split}" for split, n in self.commands.items()]) or "none"
        text = f"{self.scenes} scenes, {self.samples} samples; commands: {commands}."
        left = sum(self.skipped.values())
        if not left:
            return text + " No prompt was left out."
        reasons = _and([f"{n} {reason}" for reason, n in self.skipped.most_common()])
        were = "prompt was" if left == 1 else "prompts were"
        return (
            f"{text} {left} {were} left out (a Talk2Car command refers to exactly one object, "
            f"in front of CAM_FRONT): {reasons}."
        )


def _and(parts: list[str]) -> str:
    """``"a"``, ``"a and b"``, ``"a, b and c"``."""
    return (
        ", ".join(parts[:-1]) + (" and " if len(parts) > 1 else "") + (parts[-1] if parts else "")
    )


def ring_index(points: np.ndarray) -> np.ndarray:
    """``(N,)`` float32 the beam of each point ``(N, >=3)`` from its elevation seen from the
    LiDAR (:data:`BEAMS`: 0 the top beam)."""
    top, bottom, beams = BEAMS
    elev = np.degrees(np.arctan2(points[:, 2], np.hypot(points[:, 0], points[:, 1])))
    ring = np.rint((top - elev) / (top - bottom) * (beams - 1))
    return np.clip(ring, 0, beams - 1).astype(np.float32)


def _ego_pose(base: np.ndarray, speed: float, dt_us: int) -> np.ndarray:
    """``(4, 4)`` ego -> global ``dt_us`` after the key frame, the ego driving along its x."""
    step = np.eye(4)
    step[0, 3] = speed * dt_us * 1e-6
    return base @ step


def _camera(frame: SourceFrame) -> tuple[np.ndarray, np.ndarray, Image.Image]:
    """The CAM_FRONT intrinsics (3, 3), camera -> model (4, 4) and its 1600 x 900 image."""
    width, height = IMAGE_SIZE
    w0, h0 = frame.image_size
    scale = min(width / w0, height / h0)
    pad = ((width - round(w0 * scale)) / 2.0, (height - round(h0 * scale)) / 2.0)
    p2 = frame.calib.P2
    k = np.array([[p2[0, 0] * scale, 0.0, p2[0, 2] * scale + pad[0]],
                  [0.0, p2[1, 1] * scale, p2[1, 2] * scale + pad[1]], [0.0, 0.0, 1.0]])  # fmt: skip
    canvas = Image.new("RGB", IMAGE_SIZE, (96, 96, 96))
    if frame.image_path is not None:
        with Image.open(frame.image_path) as img:
            resized = img.convert("RGB").resize((round(w0 * scale), round(h0 * scale)))
        canvas.paste(resized, (int(pad[0]), int(pad[1])))
    return k, np.linalg.inv(frame.calib.velo_to_cam), canvas


def _annotation(
    actor: Actor, model_to_global: np.ndarray, lidar: np.ndarray, radar: np.ndarray
) -> dict:
    c, s = np.cos(actor.box[6]), np.sin(actor.box[6])
    heading = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    attributes = object_class(actor.cls).attributes
    attribute = attributes[0 if actor.is_moving else 1] if attributes else None
    return {
        "translation": [float(v) for v in transform(actor.box[:3], model_to_global)[0]],
        "size": [float(actor.box[4]), float(actor.box[3]), float(actor.box[5])],
        "rotation": [float(v) for v in quaternion_from_matrix(model_to_global[:3, :3] @ heading)],
        "attribute_tokens": [token("attribute", attribute)] if attribute else [],
        "visibility_token": "4",
        "num_lidar_pts": int(points_in_boxes(lidar[:, :3], actor.box[None])[:, 0].sum()),
        "num_radar_pts": int(points_in_boxes(radar[:, :3], actor.box[None])[:, 0].sum()),
    }


def _box_2d(to_camera: np.ndarray, k: np.ndarray, box: np.ndarray) -> tuple[float, ...] | None:
    """``(x, y, w, h)`` of the projected box clipped to the image, or None when any corner is
    not in front of the camera."""
    corners = transform(box_corners(box[None])[0], to_camera)
    if (corners[:, 2] <= 0.1).any():
        return None
    uv = corners @ k.T
    uv = uv[:, :2] / uv[:, 2:]
    lo = np.clip(uv.min(axis=0), 0, IMAGE_SIZE)
    hi = np.clip(uv.max(axis=0), 0, IMAGE_SIZE)
    if (hi - lo <= 0).any():
        return None
    return (float(lo[0]), float(lo[1]), float(hi[0] - lo[0]), float(hi[1] - lo[1]))


def export_frames(
    frames: Sequence[SourceFrame],
    out: str | Path,
    *,
    seed: int = 0,
    version: str = "v1.0-trainval",
    scan_period: float = 0.1,
    sentence: Sentence | None = None,
) -> ExportReport:
    """Write ``frames`` as a nuScenes root ``out`` (``version/`` tables, ``samples/``, ``sweeps/``,
    ``maps/``) with Talk2Car command files ``out/commands/{split}_commands.json``.

    Args:
        frames: The frames, grouped by world in order (a world's frames are consecutive).
        out: The root folder.
        seed: Seeds the random global pose of every sample.
        version: The version folder's name.
        scan_period: Seconds between the source's accumulated radar scans.
        sentence: How a single-referent prompt becomes a command's sentence (called with the
            prompt's text, its referent and a key of the export's seed, the frame and the
            prompt, for a deterministic draw; the language that phrases it lives above this
            room: :func:`scenes.export_nuscenes.command_sentence`); None: the text as written.
    """
    out = Path(out)
    rng = np.random.default_rng(seed)
    w = TableWriter()
    lidar_cs = pose_matrix(*LIDAR_MOUNT)
    commands: dict[str, list[Talk2CarCommand]] = {}
    split_scenes: dict[str, list[str]] = {}
    skipped: Counter[str] = Counter()
    last: dict[str, dict] = {}
    instances: dict[tuple[int, int], dict] = {}
    scene_rec: dict | None = None
    samples = 0
    for f_index, frame in enumerate(frames):
        if scene_rec is None or scene_rec["_world"] != frame.world:
            scene_rec, last, base_time = _start_scene(w, frame, len(w.records["scene"])), {}, 0
            base_time = 1_533_000_000_000_000 + len(w.records["scene"]) * 100_000_000
        t0 = base_time + scene_rec["nbr_samples"] * SAMPLE_PERIOD_US
        log_file = w.records["log"][-1]["logfile"]
        sample_token = token("sample", f_index)
        prev_sample = scene_rec["last_sample_token"]
        w.add("sample", {"token": sample_token, "timestamp": t0, "prev": prev_sample, "next": "",
                         "scene_token": scene_rec["token"]})  # fmt: skip
        if prev_sample:
            next(r for r in reversed(w.records["sample"]) if r["token"] == prev_sample)["next"] = (
                sample_token
            )
        else:
            scene_rec["first_sample_token"] = sample_token
        scene_rec["last_sample_token"] = sample_token
        scene_rec["nbr_samples"] += 1
        samples += 1
        yaw = rng.uniform(-np.pi, np.pi)
        base = pose_matrix([*rng.uniform(300.0, 2000.0, 2), 0.0], quaternion_from_yaw(yaw))
        model_to_global = base @ lidar_cs @ MODEL_TO_LIDAR

        add_data = _DataWriter(w, out, t0, base, frame.ego_speed, f_index, scene_rec["token"],
                               log_file, sample_token, last, model_to_global)  # fmt: skip
        _, to_sensor, name = add_data("LIDAR_TOP", lidar_cs, 0, True, "pcd.bin", {})
        pts = transform(frame.lidar[:, :3], to_sensor)
        write_lidar(out / name, np.c_[pts, frame.lidar[:, 3], ring_index(pts)])

        scans = int(-frame.radar[:, 6].min()) + 1 if len(frame.radar) else 1
        assign = _radar_of(frame.radar)
        for k in range(scans - 1, -1, -1):
            for r, channel in enumerate(RADAR_CHANNELS):
                mount, boresight, delay = RADAR_MOUNTS[channel]
                cs = pose_matrix(mount, quaternion_from_yaw(boresight))
                dt = delay - round(k * scan_period * 1e6)
                _, to_sensor, name = add_data(channel, cs, dt, k == 0, "pcd", {})
                sel = frame.radar[(assign == r) & (frame.radar[:, 6] == -k)]
                write_radar(
                    out / name,
                    radial_components(
                        transform(sel[:, :3], to_sensor), sel[:, 3], sel[:, 4], sel[:, 5]
                    ),
                )

        k_cam, cam_to_model, image = _camera(frame)
        cam_cs = lidar_cs @ MODEL_TO_LIDAR @ cam_to_model
        extra = {"intrinsic": k_cam.tolist()}
        cam_token, to_camera, name = add_data(
            "CAM_FRONT", cam_cs, CAMERA_DELAY_US, True, "jpg", extra
        )
        w.records["sample_data"][-1].update(width=IMAGE_SIZE[0], height=IMAGE_SIZE[1])
        buffer = io.BytesIO()
        image.save(buffer, format="JPEG", quality=90)
        atomic_write_bytes(out / name, buffer.getvalue())

        ann_token: dict[int, str] = {}
        for actor in frame.actors:
            inst = instances.get((frame.world, actor.actor_id))
            ann = {"token": token("sample_annotation", f_index, actor.actor_id), "sample_token": sample_token,
                   **_annotation(actor, model_to_global, frame.lidar, frame.radar), "prev": "", "next": ""}  # fmt: skip
            if inst is None:
                inst = w.add("instance", {"token": token("instance", frame.world, actor.actor_id),
                                          "category_token": token("category", CLASS_CATEGORY[actor.cls]),
                                          "nbr_annotations": 0, "first_annotation_token": ann["token"],
                                          "last_annotation_token": ""})  # fmt: skip
                instances[(frame.world, actor.actor_id)] = inst
            else:
                ann["prev"] = inst["last_annotation_token"]
                next(
                    r for r in reversed(w.records["sample_annotation"]) if r["token"] == ann["prev"]
                )["next"] = ann["token"]
            ann["instance_token"] = inst["token"]
            inst["nbr_annotations"] += 1
            inst["last_annotation_token"] = ann["token"]
            inst["_last"] = w.add("sample_annotation", ann)
            ann_token[actor.actor_id] = ann["token"]

        by_id = {a.actor_id: a for a in frame.actors}
        for p_index, prompt in enumerate(frame.prompts):
            split_scenes.setdefault(prompt.split, [])
            if scene_rec["token"] not in split_scenes[prompt.split]:
                split_scenes[prompt.split].append(scene_rec["token"])
            if len(prompt.referent_ids) != 1:
                count = len(prompt.referent_ids)
                skipped[f"with {count} referents" if count else "with no referent"] += 1
                continue
            actor = by_id[prompt.referent_ids[0]]
            box_2d = _box_2d(to_camera, k_cam, actor.box)
            if box_2d is None:
                skipped["whose referent is not wholly in front of CAM_FRONT"] += 1
                continue
            n = len(commands.setdefault(prompt.split, []))
            commands[prompt.split].append(Talk2CarCommand(
                command_token=token("command", prompt.sample_id),
                text=(
                    prompt.text
                    if sentence is None
                    else sentence(prompt.text, actor, (seed, f_index, p_index))
                ),
                scene_token=scene_rec["token"], sample_token=sample_token, cam_token=cam_token,
                box_token=ann_token[actor.actor_id], category=CLASS_CATEGORY[actor.cls],
                box_camera=model_box_to_camera(to_camera, actor.box), box_2d=box_2d,
                t2c_img=f"img_{prompt.split}_{n}.jpg"))  # fmt: skip
    for rec in w.records["scene"]:
        rec.pop("_world")
    for rec in w.records["instance"]:
        rec.pop("_last")
    w.write(out, version)
    for split, scenes in split_scenes.items():
        write_commands(out / "commands", split, scenes, commands.get(split, []))
    return ExportReport(
        len(w.records["scene"]), samples, {s: len(c) for s, c in commands.items()}, skipped
    )


class _DataWriter:
    """Adds one sample's sample_data records (with their ego poses and calibrated sensors),
    each channel linked to its previous one."""

    def __init__(self, w: TableWriter, out: Path, t0: int, base: np.ndarray, speed: float,
                 index: int, scene: str, log_file: str, sample: str, last: dict[str, dict],
                 model_to_global: np.ndarray) -> None:  # fmt: skip
        self.w, self.out, self.t0, self.base, self.speed = w, out, t0, base, speed
        self.index, self.scene, self.log_file, self.sample = index, scene, log_file, sample
        self.last, self.model_to_global = last, model_to_global

    def __call__(
        self, channel: str, cs: np.ndarray, dt: int, key: bool, ext: str, extra: dict
    ) -> tuple[str, np.ndarray, str]:
        """Add a sample_data ``dt`` µs after the key frame; returns its token, the model ->
        sensor transform and the file name (relative to the root)."""
        w, time = self.w, self.t0 + dt
        pose = _ego_pose(self.base, self.speed, dt)
        pose_token = token("ego_pose", channel, self.index, dt)
        w.add("ego_pose", {"token": pose_token, "timestamp": time,
                           "translation": [float(v) for v in pose[:3, 3]],
                           "rotation": [float(v) for v in quaternion_from_matrix(pose[:3, :3])]})  # fmt: skip
        cs_token = _calibrated(w, channel, cs, self.scene, extra.pop("intrinsic", []))
        sd_token = token("sample_data", channel, self.index, dt)
        folder = "samples" if key else "sweeps"
        filename = f"{folder}/{channel}/{self.log_file}__{channel}__{time}.{ext}"
        prev = self.last.get(channel)
        rec = {"token": sd_token, "sample_token": self.sample, "ego_pose_token": pose_token,
               "calibrated_sensor_token": cs_token, "timestamp": time,
               "fileformat": ext.split(".")[-1], "is_key_frame": key, "height": 0, "width": 0,
               "filename": filename, "prev": prev["token"] if prev else "", "next": "", **extra}  # fmt: skip
        if prev:
            prev["next"] = sd_token
        self.last[channel] = w.add("sample_data", rec)
        (self.out / filename).parent.mkdir(parents=True, exist_ok=True)
        return sd_token, np.linalg.inv(pose @ cs) @ self.model_to_global, filename


def _start_scene(w: TableWriter, frame: SourceFrame, index: int) -> dict:
    """A new log, map and scene record for a world."""
    log = w.add("log", {"token": token("log", frame.world), "logfile": f"synth-{frame.world:05d}",
                        "vehicle": "synthetic", "date_captured": "2024-01-01", "location": "synthetic"})  # fmt: skip
    if not w.records["map"]:
        w.add("map", {"token": token("map"), "log_tokens": [], "category": "semantic_prior",
                      "filename": "maps/synthetic.png"})  # fmt: skip
    w.records["map"][0]["log_tokens"].append(log["token"])
    weather = {"rain": "Rain, ", "fog": "Fog, "}.get(frame.weather, "")
    return w.add("scene", {"token": token("scene", frame.world), "name": f"scene-{index + 1:04d}",
                           "description": f"{weather}synthetic world {frame.world}, {frame.weather}",
                           "log_token": log["token"], "nbr_samples": 0, "first_sample_token": "",
                           "last_sample_token": "", "_world": frame.world})  # fmt: skip


def _calibrated(w: TableWriter, channel: str, cs: np.ndarray, scene: str, intrinsic: list) -> str:
    """The calibrated_sensor token of a sensor mount in a scene (one record per distinct mount)."""
    key = token("calibrated_sensor", channel, scene, np.round(cs, 9).tobytes(), str(intrinsic))
    if not any(r["token"] == key for r in w.records["calibrated_sensor"][-24:]):
        w.add("calibrated_sensor", {"token": key, "sensor_token": token("sensor", channel),
                                    "translation": [float(v) for v in cs[:3, 3]],
                                    "rotation": [float(v) for v in quaternion_from_matrix(cs[:3, :3])],
                                    "camera_intrinsic": intrinsic})  # fmt: skip
    return key


def _radar_of(radar: np.ndarray) -> np.ndarray:
    """``(M,)`` the index into RADAR_CHANNELS of the radar whose boresight is closest to each
    point's azimuth seen from that radar (model frame = ego axes)."""
    if not len(radar):
        return np.zeros(0, dtype=int)
    offsets = []
    for channel in RADAR_CHANNELS:
        mount, boresight, _ = RADAR_MOUNTS[channel]
        lt = np.asarray(LIDAR_MOUNT[0])
        az = np.arctan2(radar[:, 1] - (mount[1] - lt[1]), radar[:, 0] - (mount[0] - lt[0]))
        offsets.append(np.abs(np.angle(np.exp(1j * (az - boresight)))))
    return np.argmin(np.stack(offsets, axis=1), axis=1)
