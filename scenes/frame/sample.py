"""The neutral frame of every dataset family: :class:`Sample` (a frame's sensors, one prompt and
the boxes it refers to, in the LiDAR frame) and :class:`RootError` (a root that cannot be read).

A family's reader (:class:`scenes.talk2radar.root.Talk2RadarRoot`,
:class:`scenes.nuscenes.source.NuScenesSource`) loads its frames as :class:`Sample`; everything
above the dataset layer (the model's training and evaluation, the app, the annotation tools) reads
only this type and :class:`scenes.frame.source.FrameSource`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from scenes.frame.image import label_image_size, read_image, warn_principal_point
from scenes.frame.kitti import ObjectLabel
from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.calib import Calibration
from scenes.utils.errors import RootError

__all__ = ["RootError", "Sample"]


@dataclass(frozen=True)
class Sample:
    """One grounding sample: a frame's sensors, one prompt and the boxes it refers to.

    Attributes:
        sample_id: 5-digit frame id.
        lidar: ``(N, 4)`` float32 ``x, y, z, intensity``, LiDAR frame.
        radar: ``(M, 7)`` float32 ``x, y, z, rcs, v_r, v_r_compensated, time``, LiDAR frame.
        boxes: ``(K, 7)`` float64 referred boxes of the root's class set, LiDAR frame.
        classes: ``K`` class names of that set (Car, Pedestrian, Cyclist for ``vod``).
        prompt: The sentence, or None where the root has no prompt folder.
        calib: LiDAR calibration (LiDAR -> camera).
        radar_calib: Radar calibration (radar -> camera), or None without a radar tree.
        labels: Every ``label_2`` line, non-metric classes included.
        meta: The sidecar, where present.
        image_path: The camera image file (``image_2/<id>.jpg``), or None where there is none;
            :attr:`image` reads it.
    """

    sample_id: str
    lidar: np.ndarray = field(repr=False)
    radar: np.ndarray = field(repr=False)
    boxes: np.ndarray = field(repr=False)
    classes: tuple[str, ...]
    prompt: str | None
    calib: Calibration = field(repr=False)
    radar_calib: Calibration | None = field(repr=False, default=None)
    labels: tuple[ObjectLabel, ...] = field(repr=False, default=())
    meta: SampleMeta | None = field(repr=False, default=None)
    image_path: Path | None = field(repr=False, default=None)

    @cached_property
    def image(self) -> np.ndarray | None:
        """The camera image ``(H, W, 3)`` uint8 RGB (row 0 at the top; pixel coordinates as
        ``calib.P2`` projects), read on first access and kept; None without an image file.

        Warns (``UserWarning``, naming the file) when the image size puts P2's principal point
        far from the image centre (:func:`scenes.frame.image.check_principal_point`).

        Raises:
            scenes.frame.image.ImageError: the file is unreadable, corrupt or truncated.
        """
        if self.image_path is None:
            return None
        image = read_image(self.image_path)
        height, width = image.shape[:2]
        principal = (float(self.calib.P2[0, 2]), float(self.calib.P2[1, 2]))
        warn_principal_point((width, height), principal, str(self.image_path))
        return image

    @cached_property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)`` the 2D boxes of this sample's ``label_2`` are clipped to: its camera
        image's (header only), VoD's 1936 x 1216 without one (:func:`label_image_size`).

        Raises:
            scenes.frame.image.ImageError: the image file is unreadable.
        """
        return label_image_size(self.image_path)
