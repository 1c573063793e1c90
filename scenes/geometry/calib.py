"""View-of-Delft calibration files and the camera <-> sensor conversions of points and boxes.

A VoD calib file (KITTI-like, one ``Key: values`` per line) holds ``P0..P3`` (3x4), ``R0_rect`` (3x3),
``Tr_velo_to_cam`` (3x4: sensor -> camera, where "velo" is the LiDAR in ``lidar/`` and the radar in
``radar*/``) and an *empty* ``Tr_imu_to_velo`` line. ``lidar2cam = R0_rect · Tr_velo_to_cam`` (4x4)
and ``lidar2img = P2 · lidar2cam``.

Box conventions at the IO boundary (the Talk2Radar / mmdet3d rules, spec §1.7):

- camera label: bottom centre ``(x, y, z)`` in the camera frame, dimensions ``h, w, l``,
  ``rotation_y`` about the camera's y axis (pointing down), in ``[-pi, pi)``;
- sensor box: geometric centre, ``l, w, h``, ``yaw = -rotation_y - pi/2`` (wrapped), and back
  ``rotation_y = -yaw - pi/2``;
- alpha = ``rotation_y + atan2(y_sensor, x_sensor)`` of the box centre, wrapped;
- 2D box: the 8 corners of the *camera* box projected with P2 and clipped to the image.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenes.geometry.boxes import wrap_yaw
from scenes.utils.textfile import read_text_file

IMAGE_SIZE: tuple[int, int] = (1936, 1216)
"""VoD camera image ``(width, height)`` in pixels."""

VOD_INTRINSICS = (1495.468642, 1495.468642, 961.272442, 624.89592)
"""VoD camera ``fx, fy, cx, cy`` (all four P matrices are identical, with no translation)."""

LIDAR_HEIGHT = 1.70
"""Height of the (synthetic) LiDAR above the ground in metres: the ground is ``z = -LIDAR_HEIGHT``."""

RADAR_IN_LIDAR = (2.51, 0.0, -1.15)
"""Synthetic radar origin in the LiDAR frame: about 2.51 m ahead and 1.15 m below (VoD-like)."""

CAMERA_IN_LIDAR = (0.92, 0.15, -0.46)
"""Synthetic camera origin in the LiDAR frame (VoD's example calib puts the LiDAR at
``(0.15, -0.46, -0.92)`` in camera coordinates, which for an untilted camera is this)."""

_REQUIRED = ("P2", "Tr_velo_to_cam")


class CalibrationError(ValueError):
    """A calibration file is malformed; the message names the file and line."""


def _to4x4(m: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[: m.shape[0], : m.shape[1]] = m
    return out


@dataclass(frozen=True)
class Calibration:
    """One VoD calibration (camera intrinsics + sensor-to-camera extrinsics).

    Attributes:
        P2: ``(3, 4)`` camera projection.
        R0_rect: ``(3, 3)`` rectification (identity in VoD).
        Tr_velo_to_cam: ``(3, 4)`` sensor -> camera.
        P0, P1, P3: kept for writing files back verbatim (default: equal to P2).
    """

    P2: np.ndarray = field(repr=False)
    R0_rect: np.ndarray = field(repr=False)
    Tr_velo_to_cam: np.ndarray = field(repr=False)
    P0: np.ndarray | None = field(default=None, repr=False)
    P1: np.ndarray | None = field(default=None, repr=False)
    P3: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        for name, shape in (("P2", (3, 4)), ("R0_rect", (3, 3)), ("Tr_velo_to_cam", (3, 4))):
            arr = np.asarray(getattr(self, name), dtype=np.float64).reshape(shape)
            object.__setattr__(self, name, arr)
        for name in ("P0", "P1", "P3"):
            value = getattr(self, name)
            arr = self.P2 if value is None else np.asarray(value, dtype=np.float64).reshape(3, 4)
            object.__setattr__(self, name, arr)

    @property
    def velo_to_cam(self) -> np.ndarray:
        """``(4, 4)`` sensor -> rectified camera (mmdet3d's ``lidar2cam``)."""
        return _to4x4(self.R0_rect) @ _to4x4(self.Tr_velo_to_cam)

    @property
    def cam_to_velo(self) -> np.ndarray:
        """``(4, 4)`` rectified camera -> sensor."""
        return np.linalg.inv(self.velo_to_cam)

    @property
    def velo_to_img(self) -> np.ndarray:
        """``(4, 4)`` sensor -> image (``P2 · lidar2cam``)."""
        return _to4x4(self.P2) @ self.velo_to_cam

    def to_text(self) -> str:
        """The calib file text, VoD style (with the empty ``Tr_imu_to_velo:`` line)."""

        def fmt(m: np.ndarray) -> str:
            return " ".join(f"{v:.12e}" for v in np.asarray(m).reshape(-1))

        lines = [
            f"P0: {fmt(self.P0)}",
            f"P1: {fmt(self.P1)}",
            f"P2: {fmt(self.P2)}",
            f"P3: {fmt(self.P3)}",
            f"R0_rect: {fmt(self.R0_rect)}",
            f"Tr_velo_to_cam: {fmt(self.Tr_velo_to_cam)}",
            "Tr_imu_to_velo:",
        ]
        return "\n".join(lines) + "\n"

    @staticmethod
    def from_text(text: str, source: str = "<calib>") -> Calibration:
        """Parse calib text. Tolerates empty lines and keys without values (``Tr_imu_to_velo``);
        fails with the file and line on a malformed value and when P2 or Tr_velo_to_cam is missing."""
        values: dict[str, np.ndarray] = {}
        sizes = {"P0": 12, "P1": 12, "P2": 12, "P3": 12, "R0_rect": 9, "Tr_velo_to_cam": 12}
        for lineno, raw in enumerate(text.splitlines(), start=1):
            line = raw.strip()
            if not line:
                continue
            if ":" not in line:
                raise CalibrationError(f"{source}:{lineno}: expected 'Key: values', got {raw!r}")
            key, _, rest = line.partition(":")
            key = key.strip()
            parts = rest.split()
            if not parts or key not in sizes:
                continue  # e.g. the empty Tr_imu_to_velo line, or an unknown key
            try:
                nums = np.array([float(p) for p in parts])
            except ValueError as exc:
                raise CalibrationError(f"{source}:{lineno}: {key} has a non-numeric value") from exc
            if len(nums) != sizes[key]:
                raise CalibrationError(
                    f"{source}:{lineno}: {key} needs {sizes[key]} values, got {len(nums)}"
                )
            if not np.all(np.isfinite(nums)):
                raise CalibrationError(f"{source}:{lineno}: {key} has a non-finite value")
            values[key] = nums
        for key in _REQUIRED:
            if key not in values:
                raise CalibrationError(f"{source}: missing {key}")
        calib = Calibration(
            P2=values["P2"].reshape(3, 4),
            R0_rect=values.get("R0_rect", np.eye(3).reshape(-1)).reshape(3, 3),
            Tr_velo_to_cam=values["Tr_velo_to_cam"].reshape(3, 4),
            P0=values.get("P0"),
            P1=values.get("P1"),
            P3=values.get("P3"),
        )
        _check_invertible(calib, source)
        return calib


MAX_CONDITION = 1e12
"""A ``R0_rect · Tr_velo_to_cam`` with a larger condition number is refused as singular: its
inverse (camera -> sensor, used for every label and for the radar points) would be meaningless."""


def _check_invertible(calib: Calibration, source: str) -> None:
    """Raise :class:`CalibrationError` when the sensor -> camera transform cannot be inverted."""
    with np.errstate(all="ignore"):
        matrix = calib.velo_to_cam
        try:
            condition = float(np.linalg.cond(matrix)) if np.all(np.isfinite(matrix)) else np.inf
        except np.linalg.LinAlgError:
            condition = np.inf
    if not np.isfinite(condition) or condition > MAX_CONDITION:
        raise CalibrationError(
            f"{source}: R0_rect · Tr_velo_to_cam is singular (not invertible; condition number "
            f"{condition:.3g}), so camera boxes cannot be brought into the sensor frame"
        )


def read_calib(path: str | Path) -> Calibration:
    """Read a VoD calib file; errors name the file and line.

    Raises:
        CalibrationError: a missing, unreadable, non-UTF-8 or binary file, a malformed line, a
            missing matrix, or a singular sensor -> camera transform.
    """
    path = Path(path)
    text = read_text_file(path, "calib file", CalibrationError)
    return Calibration.from_text(text, source=str(path))


_LIDAR_TO_CAM_ROTATION = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
"""Axis change LiDAR (x fwd, y left, z up) -> camera (x right, y down, z fwd), no tilt."""


def _intrinsics() -> np.ndarray:
    fx, fy, cx, cy = VOD_INTRINSICS
    return np.array([[fx, 0.0, cx, 0.0], [0.0, fy, cy, 0.0], [0.0, 0.0, 1.0, 0.0]])


def vod_lidar_calibration() -> Calibration:
    """A VoD-like LiDAR calibration: VoD intrinsics, an untilted camera at :data:`CAMERA_IN_LIDAR`."""
    rot = _LIDAR_TO_CAM_ROTATION
    t = -rot @ np.asarray(CAMERA_IN_LIDAR)
    return Calibration(P2=_intrinsics(), R0_rect=np.eye(3), Tr_velo_to_cam=np.c_[rot, t])


def vod_radar_calibration() -> Calibration:
    """A VoD-like radar calibration: the radar at :data:`RADAR_IN_LIDAR`, axes parallel to the LiDAR's."""
    lidar = vod_lidar_calibration()
    radar_to_lidar = np.eye(4)
    radar_to_lidar[:3, 3] = RADAR_IN_LIDAR
    tr = (_to4x4(lidar.Tr_velo_to_cam) @ radar_to_lidar)[:3]
    return Calibration(P2=_intrinsics(), R0_rect=np.eye(3), Tr_velo_to_cam=tr)


def sensor_to_lidar(lidar_calib: Calibration, sensor_calib: Calibration) -> np.ndarray:
    """``(4, 4)`` transform from another sensor's frame (e.g. the radar) into the LiDAR frame."""
    return lidar_calib.cam_to_velo @ sensor_calib.velo_to_cam


def transform_points(points: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """Apply a ``(4, 4)`` rigid transform to the xyz of ``points (N, >=3)``; other columns kept."""
    pts = np.array(points, dtype=np.float64, copy=True)
    if len(pts) == 0:
        return pts
    pts[:, :3] = pts[:, :3] @ matrix[:3, :3].T + matrix[:3, 3]
    return pts


@dataclass(frozen=True)
class CameraBoxes:
    """Boxes in the KITTI camera-label convention.

    Attributes:
        location: ``(K, 3)`` bottom centre in the rectified camera frame.
        dimensions_hwl: ``(K, 3)`` height, width, length.
        rotation_y: ``(K,)`` in ``[-pi, pi)``.
    """

    location: np.ndarray
    dimensions_hwl: np.ndarray
    rotation_y: np.ndarray


def bottom_centres(boxes: np.ndarray) -> np.ndarray:
    """Bottom-face centres ``(K, 3)`` of sensor-frame boxes ``(K, 7)`` (z at the geometric centre,
    z up), in the same frame."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    bottom = b[:, :3].copy()
    bottom[:, 2] -= b[:, 5] / 2.0
    return bottom


def boxes_lidar_to_camera(boxes: np.ndarray, calib: Calibration) -> CameraBoxes:
    """Sensor-frame boxes ``(K, 7)`` -> camera labels (spec §1.7, "sensor-frame prediction")."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    loc = transform_points(bottom_centres(b), calib.velo_to_cam)
    hwl = b[:, [5, 4, 3]]
    ry = np.asarray(wrap_yaw(-b[:, 6] - np.pi / 2.0)).reshape(-1)
    return CameraBoxes(loc, hwl, ry)


def boxes_camera_to_lidar(cam: CameraBoxes, calib: Calibration) -> np.ndarray:
    """Camera labels -> sensor-frame boxes ``(K, 7)`` with z at the geometric centre."""
    loc = np.asarray(cam.location, dtype=np.float64).reshape(-1, 3)
    hwl = np.asarray(cam.dimensions_hwl, dtype=np.float64).reshape(-1, 3)
    ry = np.asarray(cam.rotation_y, dtype=np.float64).reshape(-1)
    centre = transform_points(loc, calib.cam_to_velo)
    centre[:, 2] += hwl[:, 0] / 2.0
    yaw = np.asarray(wrap_yaw(-ry - np.pi / 2.0)).reshape(-1)
    return np.concatenate([centre, hwl[:, [2, 1, 0]], yaw[:, None]], axis=1)


def camera_box_corners(cam: CameraBoxes) -> np.ndarray:
    """Corners ``(K, 8, 3)`` of camera boxes: length along x rotated by ``rotation_y`` about y,
    height from the bottom centre upwards (towards -y)."""
    loc = np.asarray(cam.location, dtype=np.float64).reshape(-1, 3)
    h, w, length = np.asarray(cam.dimensions_hwl, dtype=np.float64).reshape(-1, 3).T
    ry = np.asarray(cam.rotation_y, dtype=np.float64).reshape(-1)
    sx = np.array([1, -1, -1, 1, 1, -1, -1, 1], dtype=np.float64) * 0.5
    sz = np.array([1, 1, -1, -1, 1, 1, -1, -1], dtype=np.float64) * 0.5
    sy = np.array([0, 0, 0, 0, -1, -1, -1, -1], dtype=np.float64)
    x = length[:, None] * sx
    y = h[:, None] * sy
    z = w[:, None] * sz
    cos, sin = np.cos(ry)[:, None], np.sin(ry)[:, None]
    rx = x * cos + z * sin
    rz = -x * sin + z * cos
    return np.stack([rx, y, rz], axis=-1) + loc[:, None, :]


_MIN_DEPTH = 0.1
"""Corners closer than this to the camera plane are clamped before the perspective division, so a
box reaching behind the camera still gives a finite (if wide) 2D box rather than a sign flip."""


def project_to_image(points_cam: np.ndarray, calib: Calibration) -> np.ndarray:
    """Project rectified-camera points ``(..., 3)`` with P2 -> pixels ``(..., 2)``."""
    pts = np.asarray(points_cam, dtype=np.float64)
    homo = np.concatenate([pts, np.ones((*pts.shape[:-1], 1))], axis=-1)
    uvw = homo @ calib.P2.T
    depth = np.maximum(uvw[..., 2:3], _MIN_DEPTH)
    return uvw[..., :2] / depth


def boxes_2d(
    cam: CameraBoxes, calib: Calibration, image_size: tuple[int, int] = IMAGE_SIZE
) -> np.ndarray:
    """Projected and clipped 2D boxes ``(K, 4)`` ``left, top, right, bottom`` in pixels."""
    uv = project_to_image(camera_box_corners(cam), calib)
    if uv.shape[0] == 0:
        return np.zeros((0, 4))
    width, height = image_size
    x1 = np.clip(uv[..., 0].min(axis=1), 0, width)
    y1 = np.clip(uv[..., 1].min(axis=1), 0, height)
    x2 = np.clip(uv[..., 0].max(axis=1), 0, width)
    y2 = np.clip(uv[..., 1].max(axis=1), 0, height)
    return np.stack([x1, y1, x2, y2], axis=1)


def alpha_from(rotation_y: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Observation angle ``(K,)``: ``rotation_y + atan2(y, x)`` of the sensor-frame centre, wrapped."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    return np.asarray(wrap_yaw(np.asarray(rotation_y) + np.arctan2(b[:, 1], b[:, 0]))).reshape(-1)
