"""Reading a nuScenes root as it comes: :class:`NuScenesRoot` and the :class:`NuScenesFrame` it
loads (skeleton: the contract's names; the reading lands next)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenes.geometry.calib import Calibration

__all__ = ["NuScenesFrame", "NuScenesRoot"]


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


class NuScenesRoot:
    """A nuScenes root: ``path`` holds ``v1.0-*/`` (the tables), ``samples/`` and ``sweeps/``.

    Args:
        path: The root folder.
        version: The version folder's name (``v1.0-trainval``, ``v1.0-mini``, ...); None = the one
            present (an error naming the folder if none or several).
        lidar_sweeps: LIDAR_TOP sweeps accumulated per frame (1 = the key frame only).
        radar_sweeps: Sweeps per radar accumulated per frame.

    Attributes:
        version: The version folder read.
        samples: Sample tokens, by scene then time.
    """

    def __init__(
        self,
        path: str | Path,
        version: str | None = None,
        lidar_sweeps: int = 1,
        radar_sweeps: int = 1,
    ) -> None:
        raise NotImplementedError

    def frame(self, sample_token: str) -> NuScenesFrame:
        """The sample's sensors and annotations in the model frame."""
        raise NotImplementedError

    def sample_of_camera(self, cam_front_sample_data_token: str) -> str:
        """The sample token of a CAM_FRONT sample_data token (Talk2Car's ``sample_token``)."""
        raise NotImplementedError

    def scene_description(self, sample_token: str) -> str:
        """The description of the sample's scene (``Rain``, ``Night`` mark those conditions)."""
        raise NotImplementedError
