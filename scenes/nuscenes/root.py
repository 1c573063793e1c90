"""Reading a nuScenes root as it comes: :class:`NuScenesRoot` and the :class:`NuScenesFrame` it
loads.

A root holds ``v1.0-*/`` (the 13 tables, :mod:`scenes.nuscenes.tables`), ``samples/`` and
``sweeps/`` (:mod:`scenes.nuscenes.sensorfiles`). A frame is one sample in the model frame: the
key frame's LIDAR_TOP turned so that x points forward (:data:`~scenes.nuscenes.geometry.LIDAR_TO_MODEL`).
Every sensor file comes through its own sample_data's calibrated_sensor and ego_pose, as the
devkit's ``from_file_multisweep`` does: sensor -> ego(t) -> global -> ego(t_key) -> LIDAR_TOP(key);
sweeps follow the ``prev`` links of each channel (fewer when the chain ends). The radar channels
are :mod:`scenes.nuscenes.radar`'s. The LiDAR's ring index is read and not kept (the model takes
x, y, z, intensity); unlike the devkit, no point close to the sensor is removed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenes.geometry.calib import Calibration
from scenes.nuscenes.geometry import LIDAR_TO_MODEL, boxes_from_poses, pose_matrix
from scenes.nuscenes.motion import (
    MAX_SPEED,
    MAX_TIME_GAP,
    attribute_velocity,
    combine,
    radar_velocity,
)
from scenes.nuscenes.radar import RADAR_CHANNELS, default_filter, model_channels
from scenes.nuscenes.sensorfiles import read_lidar, read_radar
from scenes.nuscenes.tables import NuScenesError, Tables, read_tables, version_folder
from scenes.utils.textfile import claim_root

__all__ = ["CAM_FRONT", "LIDAR_TOP", "NuScenesError", "NuScenesFrame", "NuScenesRoot"]

LIDAR_TOP = "LIDAR_TOP"
CAM_FRONT = "CAM_FRONT"


@dataclass(frozen=True)
class NuScenesFrame:
    """One nuScenes sample in the model frame.

    Attributes:
        sample_token: The sample.
        scene_token: Its scene.
        cam_front_token: The CAM_FRONT key-frame sample_data token (Talk2Car's ``sample_token``).
        lidar: ``(N, 4)`` float32 ``x, y, z, intensity`` in the model frame (the key frame's
            LIDAR_TOP turned 90 degrees about z: x forward, y left, z up, origin at the LiDAR);
            sweeps accumulated through each sweep's own calibrated_sensor and ego_pose.
        lidar_time: ``(N,)`` float32 each point's time lag in seconds (0 for the key frame,
            negative for older sweeps).
        radar: ``(M, 7)`` float32 ``x, y, z, rcs, v_r, v_r_compensated, time`` in the model frame,
            all five radars, the devkit's default filters; ``time = -k`` for the k-th older sweep.
        radar_time: ``(M,)`` float32 seconds (0 key frame, negative older).
        boxes: ``(K, 7)`` float64 every sample_annotation of the sample, model frame.
        categories: ``K`` nuScenes category names.
        attributes: ``K`` tuples of attribute names.
        annotation_tokens: ``K`` sample_annotation tokens.
        calib: P2 = CAM_FRONT's intrinsics padded to 3x4, R0_rect = identity,
            Tr_velo_to_cam = model frame -> CAM_FRONT camera frame.
        to_camera: ``(4, 4)`` float64 the same transform (model frame -> CAM_FRONT at the camera's
            own timestamp, through global with both ego poses).
        image_path: The CAM_FRONT key-frame image, or None where the file is missing.
        image_size: ``(width, height)`` from the sample_data record.
        description: The scene's description.
        velocities: ``(K, 2)`` float64 each annotation's ground velocity in the model frame
            (m/s), NaN where the release does not tell it (:mod:`scenes.nuscenes.motion`).
    """

    sample_token: str
    scene_token: str
    cam_front_token: str
    lidar: np.ndarray = field(repr=False)
    lidar_time: np.ndarray = field(repr=False)
    radar: np.ndarray = field(repr=False)
    radar_time: np.ndarray = field(repr=False)
    boxes: np.ndarray = field(repr=False)
    categories: tuple[str, ...]
    attributes: tuple[tuple[str, ...], ...]
    annotation_tokens: tuple[str, ...]
    calib: Calibration = field(repr=False)
    to_camera: np.ndarray = field(repr=False)
    image_path: Path | None
    image_size: tuple[int, int]
    description: str
    velocities: np.ndarray | None = field(default=None, repr=False)


class NuScenesRoot:
    """A nuScenes root: ``path`` holds ``v1.0-*/`` (the tables), ``samples/`` and ``sweeps/``.

    Args:
        path: The root folder.
        version: The version folder's name (``v1.0-trainval``, ``v1.0-mini``, ...); None = the one
            present (an error naming the folder if none or several).
        lidar_sweeps: LIDAR_TOP sweeps accumulated per frame (1 = the key frame only).
        radar_sweeps: Sweeps per radar accumulated per frame.

    Attributes:
        path: The root folder.
        version: The version folder read.
        tables: The tables (:class:`~scenes.nuscenes.tables.Tables`).
        samples: Sample tokens, by scene (the scene table's order) then time.

    Raises:
        NuScenesError: a missing or malformed table (one line naming file, record and field).
    """

    def __init__(
        self,
        path: str | Path,
        version: str | None = None,
        lidar_sweeps: int = 1,
        radar_sweeps: int = 1,
    ) -> None:
        if lidar_sweeps < 1 or radar_sweeps < 1:
            raise ValueError(f"sweeps must be >= 1, got lidar {lidar_sweeps}, radar {radar_sweeps}")
        self.path = Path(path)
        claim_root(self.path)
        folder = version_folder(self.path, version)
        self.version = folder.name
        self.lidar_sweeps = lidar_sweeps
        self.radar_sweeps = radar_sweeps
        self.tables: Tables = read_tables(folder)
        t = self.tables
        self._channel: dict[str, str] = {}
        for token, cs in t.records["calibrated_sensor"].items():
            sensor = t.get("sensor", cs["sensor_token"], f"calibrated_sensor {token}")
            self._channel[token] = sensor["channel"]
        self._key_data: dict[str, dict[str, str]] = {s: {} for s in t.records["sample"]}
        for token, sd in t.records["sample_data"].items():
            if not sd["is_key_frame"]:
                continue
            channel = self._channel_of(token, sd)
            if sd["sample_token"] not in self._key_data:
                raise NuScenesError(
                    f"{t.folder / 'sample_data.json'}: record {token}: field 'sample_token': "
                    f"no sample {sd['sample_token']!r}"
                )
            self._key_data[sd["sample_token"]][channel] = token
        self._anns: dict[str, list[str]] = {s: [] for s in t.records["sample"]}
        for token, ann in t.records["sample_annotation"].items():
            if ann["sample_token"] not in self._anns:
                raise NuScenesError(
                    f"{t.folder / 'sample_annotation.json'}: record {token}: field "
                    f"'sample_token': no sample {ann['sample_token']!r}"
                )
            self._anns[ann["sample_token"]].append(token)
        scene_order = {s: i for i, s in enumerate(t.records["scene"])}
        for token, sample in t.records["sample"].items():
            if sample["scene_token"] not in scene_order:
                raise NuScenesError(
                    f"{t.folder / 'sample.json'}: record {token}: field 'scene_token': "
                    f"no scene {sample['scene_token']!r}"
                )
        self.samples: tuple[str, ...] = tuple(
            sorted(
                t.records["sample"],
                key=lambda s: (
                    scene_order[t.records["sample"][s]["scene_token"]],
                    t.records["sample"][s]["timestamp"],
                ),
            )
        )
        self._camera_sample = {
            data[CAM_FRONT]: s for s, data in self._key_data.items() if CAM_FRONT in data
        }

    def __repr__(self) -> str:
        return f"NuScenesRoot({str(self.path)!r}, version={self.version!r})"

    def _channel_of(self, token: str, sd: dict) -> str:
        channel = self._channel.get(sd["calibrated_sensor_token"])
        if channel is None:
            raise NuScenesError(
                f"{self.tables.folder / 'sample_data.json'}: record {token}: field "
                f"'calibrated_sensor_token': no calibrated_sensor {sd['calibrated_sensor_token']!r}"
            )
        return channel

    def key_data(self, sample_token: str) -> dict[str, str]:
        """Channel -> the sample's key-frame sample_data token (the devkit's ``sample['data']``)."""
        self._sample(sample_token)
        return dict(self._key_data[sample_token])

    def annotations(self, sample_token: str) -> tuple[str, ...]:
        """The sample's sample_annotation tokens, in table order (the devkit's ``anns``)."""
        self._sample(sample_token)
        return tuple(self._anns[sample_token])

    def _sample(self, sample_token: str) -> dict:
        if sample_token not in self.tables.records["sample"]:
            raise NuScenesError(f"{self.tables.folder / 'sample.json'}: no sample {sample_token!r}")
        return self.tables.records["sample"][sample_token]

    def sample_of_camera(self, cam_front_sample_data_token: str) -> str:
        """The sample token of a CAM_FRONT key-frame sample_data token (Talk2Car's
        ``sample_token``).

        Raises:
            NuScenesError: the token is not a CAM_FRONT key-frame sample_data of this root.
        """
        try:
            return self._camera_sample[cam_front_sample_data_token]
        except KeyError:
            raise NuScenesError(
                f"{self.tables.folder / 'sample_data.json'}: {cam_front_sample_data_token!r} is "
                "not a CAM_FRONT key-frame sample_data token"
            ) from None

    def scene_description(self, sample_token: str) -> str:
        """The description of the sample's scene (``Rain``, ``Night`` mark those conditions)."""
        scene = self._sample(sample_token)["scene_token"]
        return str(self.tables.get("scene", scene)["description"])

    def sensor_to_global(self, sample_data_token: str) -> np.ndarray:
        """``(4, 4)`` a sample_data's sensor frame -> global, through its own calibrated_sensor
        and ego_pose."""
        t = self.tables
        sd = t.get("sample_data", sample_data_token)
        cs = t.get(
            "calibrated_sensor", sd["calibrated_sensor_token"], f"sample_data {sample_data_token}"
        )
        pose = t.get("ego_pose", sd["ego_pose_token"], f"sample_data {sample_data_token}")
        return pose_matrix(pose["translation"], pose["rotation"]) @ pose_matrix(
            cs["translation"], cs["rotation"]
        )

    def _sweeps(self, token: str, count: int) -> list[tuple[int, dict, str]]:
        """``(k, sample_data, token)`` of a key frame and up to ``count - 1`` older sweeps."""
        out = []
        for k in range(count):
            sd = self.tables.get("sample_data", token)
            out.append((k, sd, token))
            if not sd["prev"]:
                break
            token = sd["prev"]
        return out

    def model_from_global(self, sample_token: str) -> np.ndarray:
        """``(4, 4)`` global -> the sample's model frame (its key LIDAR_TOP, turned)."""
        data = self.key_data(sample_token)
        if LIDAR_TOP not in data:
            raise NuScenesError(
                f"{self.tables.folder / 'sample_data.json'}: sample {sample_token} has no "
                f"{LIDAR_TOP} key frame"
            )
        return LIDAR_TO_MODEL @ np.linalg.inv(self.sensor_to_global(data[LIDAR_TOP]))

    def to_camera(self, sample_token: str) -> np.ndarray:
        """``(4, 4)`` the sample's model frame -> its CAM_FRONT camera frame (x right, y down,
        z forward) at the camera's own timestamp, through global with both ego poses."""
        data = self.key_data(sample_token)
        if CAM_FRONT not in data:
            raise NuScenesError(
                f"{self.tables.folder / 'sample_data.json'}: sample {sample_token} has no "
                f"{CAM_FRONT} key frame"
            )
        return np.linalg.inv(self.sensor_to_global(data[CAM_FRONT])) @ np.linalg.inv(
            self.model_from_global(sample_token)
        )

    def annotation_boxes(
        self, sample_token: str
    ) -> tuple[np.ndarray, tuple[str, ...], tuple[tuple[str, ...], ...]]:
        """The sample's annotations without its sensor files: ``(K, 7)`` float64 boxes in the
        model frame, the ``K`` category names and attribute names, in :meth:`annotations` order."""
        t = self.tables
        tokens = self.annotations(sample_token)
        anns = [t.get("sample_annotation", a) for a in tokens]
        boxes = boxes_from_poses(
            np.array([a["translation"] for a in anns]).reshape(-1, 3),
            np.array([a["size"] for a in anns]).reshape(-1, 3),
            np.array([a["rotation"] for a in anns]).reshape(-1, 4),
            self.model_from_global(sample_token),
        )
        categories, attributes = [], []
        for token, a in zip(tokens, anns, strict=True):
            instance = t.get("instance", a["instance_token"], f"sample_annotation {token}")
            category = t.get(
                "category", instance["category_token"], f"instance {a['instance_token']}"
            )
            categories.append(str(category["name"]))
            attributes.append(
                tuple(
                    str(t.get("attribute", at, f"sample_annotation {token}")["name"])
                    for at in a["attribute_tokens"]
                )
            )
        return boxes, tuple(categories), tuple(attributes)

    def neighbour_velocities(self, sample_token: str) -> np.ndarray:
        """``(K, 2)`` float64 each annotation's ground velocity in the sample's model frame from
        its instance's ``prev`` and ``next`` annotations (both when both exist, else one and
        itself; NaN without one within :data:`~scenes.nuscenes.motion.MAX_TIME_GAP`, or faster
        than :data:`~scenes.nuscenes.motion.MAX_SPEED`: a root whose global poses do not hold
        one world together), in
        :meth:`annotations` order (:mod:`scenes.nuscenes.motion`, source 1)."""
        t = self.tables
        anns = t.records["sample_annotation"]
        samples = t.records["sample"]
        tokens = self.annotations(sample_token)
        turn = self.model_from_global(sample_token)[:3, :3]
        out = np.full((len(tokens), 2), np.nan)
        for i, token in enumerate(tokens):
            ann = anns[token]
            before = anns.get(ann.get("prev") or "", ann)
            after = anns.get(ann.get("next") or "", ann)
            if before is after:
                continue
            times = [samples.get(a["sample_token"], {}).get("timestamp") for a in (before, after)]
            if any(not isinstance(v, (int, float)) for v in times):
                continue
            gap = (times[1] - times[0]) * 1e-6
            if not 0 < gap <= MAX_TIME_GAP:
                continue
            moved = np.subtract(after["translation"], before["translation"], dtype=np.float64)
            velocity = (turn @ moved)[:2] / gap
            if np.hypot(*velocity) <= MAX_SPEED:
                out[i] = velocity
        return out

    def frame(self, sample_token: str) -> NuScenesFrame:
        """The sample's sensors and annotations in the model frame (:class:`NuScenesFrame`).

        Raises:
            NuScenesError: no such sample, a sample without a LIDAR_TOP or CAM_FRONT key frame,
                a dangling token (names the table and who refers to it).
            scenes.nuscenes.sensorfiles.SensorFileError: a missing or malformed sensor file.
        """
        sample = self._sample(sample_token)
        data = self._key_data[sample_token]
        for channel in (LIDAR_TOP, CAM_FRONT):
            if channel not in data:
                raise NuScenesError(
                    f"{self.tables.folder / 'sample_data.json'}: sample {sample_token} has no "
                    f"{channel} key frame"
                )
        t = self.tables
        ref_time = t.get("sample_data", data[LIDAR_TOP])["timestamp"]
        model_from_global = self.model_from_global(sample_token)

        clouds, times = [], []
        for _, sd, token in self._sweeps(data[LIDAR_TOP], self.lidar_sweeps):
            pts = read_lidar(self.path / sd["filename"])
            m = model_from_global @ self.sensor_to_global(token)
            clouds.append(np.c_[pts[:, :3] @ m[:3, :3].T + m[:3, 3], pts[:, 3]])
            times.append(np.full(len(pts), (sd["timestamp"] - ref_time) * 1e-6))
        lidar = np.concatenate(clouds).astype(np.float32)
        lidar_time = np.concatenate(times).astype(np.float32)

        radars, radar_times = [np.zeros((0, 7))], [np.zeros(0)]
        for channel in RADAR_CHANNELS:
            if channel not in data:
                continue
            for k, sd, token in self._sweeps(data[channel], self.radar_sweeps):
                rec = read_radar(self.path / sd["filename"])
                rec = rec[default_filter(rec)]
                m = model_from_global @ self.sensor_to_global(token)
                xyz = np.c_[rec["x"], rec["y"], rec["z"]].astype(np.float64)
                radars.append(
                    np.c_[xyz @ m[:3, :3].T + m[:3, 3], model_channels(rec), np.full(len(rec), -k)]
                )
                radar_times.append(np.full(len(rec), (sd["timestamp"] - ref_time) * 1e-6))
        radar = np.concatenate(radars).astype(np.float32)
        radar_time = np.concatenate(radar_times).astype(np.float32)

        boxes, categories, attributes = self.annotation_boxes(sample_token)

        cam_token = data[CAM_FRONT]
        cam_sd = t.get("sample_data", cam_token)
        cam_cs = t.get("calibrated_sensor", cam_sd["calibrated_sensor_token"])
        intrinsic = _camera_intrinsic(t, cam_sd["calibrated_sensor_token"], cam_cs)
        to_camera = self.to_camera(sample_token)
        calib = Calibration(
            P2=np.c_[intrinsic, np.zeros(3)], R0_rect=np.eye(3), Tr_velo_to_cam=to_camera[:3]
        )
        image = self.path / cam_sd["filename"]
        width, height = cam_sd.get("width", 0), cam_sd.get("height", 0)
        if not (isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0):
            raise NuScenesError(
                f"{t.folder / 'sample_data.json'}: record {cam_token}: fields 'width', 'height': "
                "a camera sample_data needs its image size"
            )
        return NuScenesFrame(
            sample_token=sample_token,
            scene_token=sample["scene_token"],
            cam_front_token=cam_token,
            lidar=lidar,
            lidar_time=lidar_time,
            radar=radar,
            radar_time=radar_time,
            boxes=boxes,
            categories=tuple(categories),
            attributes=tuple(attributes),
            annotation_tokens=tuple(self._anns[sample_token]),
            calib=calib,
            to_camera=to_camera,
            image_path=image if image.is_file() else None,
            image_size=(width, height),
            description=self.scene_description(sample_token),
            velocities=combine(
                attribute_velocity(attributes),
                self.neighbour_velocities(sample_token),
                radar_velocity(boxes, radar),
            ),
        )


def _camera_intrinsic(tables: Tables, token: str, record: dict) -> np.ndarray:
    """``(3, 3)`` float64 the CAM_FRONT intrinsics of calibrated_sensor ``token``.

    Raises:
        NuScenesError: not a 3 x 3 matrix of finite numbers, a focal length (``[0][0]``,
            ``[1][1]``) that is not > 0, or a last row other than ``0 0 1`` (names the file,
            record and field): projected 2D boxes would be meaningless (AP50 2D silently 0).
    """
    where = f"{tables.folder / 'calibrated_sensor.json'}: record {token}: field 'camera_intrinsic'"
    try:
        intrinsic = np.asarray(record["camera_intrinsic"], dtype=np.float64)
    except (TypeError, ValueError):
        intrinsic = np.zeros(0)
    if intrinsic.shape != (3, 3) or not np.isfinite(intrinsic).all():
        raise NuScenesError(f"{where}: CAM_FRONT needs a 3 x 3 matrix of finite numbers")
    fx, fy = intrinsic[0, 0], intrinsic[1, 1]
    if not (fx > 0 and fy > 0):
        raise NuScenesError(
            f"{where}: CAM_FRONT focal lengths fx = {fx:g}, fy = {fy:g}; both must be > 0"
        )
    if not np.array_equal(intrinsic[2], [0.0, 0.0, 1.0]):
        raise NuScenesError(
            f"{where}: CAM_FRONT's last row is {intrinsic[2].tolist()}; expected [0, 0, 1]"
        )
    return intrinsic
