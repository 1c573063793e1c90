"""The scene in the viewer: LiDAR and radar points, ego marker, range rings, camera presets, and the
"View" panel that controls them.

World frame = LiDAR frame (x forward, y left, z up, metres); viser's default up direction is +z.
Points are sent as float32 (viser's float16 default quantises 3 cm beyond 32 m).

- LiDAR ``(N, 4)``: coloured by height above the ground estimate (0..3 m) or by intensity.
- Radar ``(M, 7)``: coloured by ``v_r_compensated`` on the diverging map of :mod:`app.view.colors`,
  drawn as larger round points; the legend gives the m/s scale and which colour approaches.
- The ground height is estimated per frame (:func:`app.serving.navigation.estimate_ground_z`,
  :attr:`Frame.ground_z <app.serving.navigation.Frame.ground_z>`); rings, the ego marker
  and the heatmap sit on it.
- Camera presets (per browser): ``BEV`` looks straight down from 70 m over the model's range with
  forward (+x) pointing up the screen; ``Chase`` looks forward from 14 m behind and 8 m above;
  ``Camera`` puts the view at the frame's camera (its projection centre, viewing direction and
  vertical field of view, :func:`camera_view_pose`), so the cloud lines up with the camera panel's
  image (horizontally as far as the browser window's aspect ratio allows).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, replace
from typing import Literal, Protocol

import numpy as np
import viser

from app.view.boxes_view import BOX_EDGES
from app.view.colors import (
    class_legend,
    height_colors,
    height_legend,
    intensity_colors,
    intensity_legend,
    velocity_colors,
    velocity_legend,
)
from app.view.point_sizes import Eye, LegibleSizes
from scenes.geometry.boxes import box_corners
from scenes.geometry.calib import LIDAR_HEIGHT, Calibration
from scenes.geometry.classes import VOD

log = logging.getLogger(__name__)

LidarColoring = Literal["height", "intensity"]
HEIGHT_RANGE = (0.0, 3.0)
"""Heights above the ground estimate (m) mapped to the ends of the LiDAR height ramp."""

RING_STEP = 10.0
"""Range-ring spacing in metres."""

RING_MAX = 50.0
"""Largest range ring in metres."""

EGO_SIZE = (4.4, 1.8, 1.5)
"""Ego vehicle marker size ``(l, w, h)`` in metres."""

EGO_CENTRE_X = -0.8
"""x of the ego marker's centre (the LiDAR sits on the roof, slightly ahead of the middle)."""


def ring_segments(
    ground_z: float, step: float = RING_STEP, max_range: float = RING_MAX, sides: int = 96
) -> np.ndarray:
    """Circles of radius ``step, 2 step, ... <= max_range`` around the sensor on the ground.

    Returns:
        ``(R * sides, 2, 3)`` float32 segments, LiDAR frame, at height ``ground_z + 0.02``.
    """
    radii = np.arange(step, max_range + 1e-9, step)
    angles = np.linspace(0.0, 2.0 * np.pi, sides + 1)
    circle = np.stack([np.cos(angles), np.sin(angles)], axis=-1)  # (sides + 1, 2)
    pts = radii[:, None, None] * circle[None]  # (R, sides + 1, 2)
    segs = np.stack([pts[:, :-1], pts[:, 1:]], axis=2).reshape(-1, 2, 2)
    z = np.full((*segs.shape[:2], 1), ground_z + 0.02)
    return np.concatenate([segs, z], axis=-1).astype(np.float32)


def ego_segments(ground_z: float) -> np.ndarray:
    """The ego marker: the outline of an :data:`EGO_SIZE` box standing on the ground around the
    sensor, and a 3 m arrow on the ground ahead of its nose.

    Returns:
        ``(15, 2, 3)`` float32 segments, LiDAR frame (12 box edges, the arrow shaft, two barbs).
    """
    l, w, h = EGO_SIZE
    box = np.array([[EGO_CENTRE_X, 0.0, ground_z + h / 2.0, l, w, h, 0.0]])
    edges = box_corners(box)[0][np.asarray(BOX_EDGES)]
    nose, z = EGO_CENTRE_X + l / 2.0, ground_z + 0.05
    tip = np.array([nose + 3.0, 0.0, z])
    arrow = np.array(
        [
            [[nose, 0.0, z], tip],
            [tip, [nose + 2.2, 0.5, z]],
            [tip, [nose + 2.2, -0.5, z]],
        ]
    )
    return np.concatenate([edges, arrow]).astype(np.float32)


@dataclass(frozen=True)
class CameraPose:
    """A camera placement in the LiDAR frame; ``fov``: vertical field of view (radians), None to
    keep the browser's."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov: float | None = None


def bev_pose(ground_z: float, centre_x: float = 25.6, height: float = 70.0) -> CameraPose:
    """Bird's-eye view over ``x in [0, 51.2]``: forward (+x) points up the screen.

    The camera sits 1 m behind the point it looks at, so the orbit controls' +z up direction is
    not parallel to the view direction (a degenerate case for them).
    """
    return CameraPose((centre_x - 1.0, 0.0, ground_z + height), (centre_x, 0.0, ground_z))


def chase_pose(ground_z: float) -> CameraPose:
    """Behind and above the ego vehicle, looking forward down the road."""
    return CameraPose((-14.0, 0.0, ground_z + 9.0), (18.0, 0.0, ground_z))


def camera_view_pose(
    calib: Calibration, image_height: float | None = None, distance: float = 10.0
) -> CameraPose:
    """The frame's camera as a viewpoint of the 3D view (LiDAR frame).

    The position is the projection centre of ``P2 · R0_rect · Tr_velo_to_cam`` (the point it
    maps to ``(0, 0, 0)``), the view looks along the rectified camera's optical axis (+z) to a
    point ``distance`` metres ahead, ``up`` is the camera's -y, and the vertical field of view is
    ``2 atan(H / 2 / fy)`` for an image ``H = image_height`` pixels tall (``2 cy`` from P2's
    principal point when None).
    """
    m = calib.velo_to_img[:3]
    centre = -np.linalg.solve(m[:, :3], m[:, 3])
    rot = calib.velo_to_cam[:3, :3]
    forward = rot.T @ np.array([0.0, 0.0, 1.0])
    up = rot.T @ np.array([0.0, -1.0, 0.0])
    forward /= np.linalg.norm(forward)
    up /= np.linalg.norm(up)
    fy = float(calib.P2[1, 1])
    height = float(image_height) if image_height else 2.0 * float(calib.P2[1, 2])
    fov = 2.0 * math.atan(height / (2.0 * abs(fy))) if fy else math.radians(50.0)
    target = centre + distance * forward
    return CameraPose(
        tuple(float(v) for v in centre),  # type: ignore[arg-type]
        tuple(float(v) for v in target),  # type: ignore[arg-type]
        tuple(float(v) for v in up),  # type: ignore[arg-type]
        fov,
    )


def apply_pose(camera: viser.CameraHandle, pose: CameraPose) -> bool:
    """Move one browser's camera (``look_at`` last: setting ``position`` drags it along).
    Returns False, with one warning line, when viser refuses it: the browser reported a
    degenerate camera (its position on its look-at point), which only a forged message does."""
    try:
        camera.up_direction = pose.up
        if pose.fov is not None:
            camera.fov = pose.fov
        camera.position = pose.position
        camera.look_at = pose.look_at
    except ValueError as exc:
        log.warning("client %s: camera not moved: %s", camera.client.client_id, exc)
        return False
    return True


class CameraViewpoint(Protocol):
    """What the View tab needs of the camera panel (:class:`app.view.camera_panel.CameraPanel`)."""

    def view_pose(self) -> CameraPose | None:
        """The "Camera" preset of the frame shown (None: no frame)."""
        ...

    def set_velocity_range(self, velocity_range: float) -> None:
        """Follow the radar colour scale (m/s)."""
        ...


PRESETS = ("BEV", "Chase", "Camera")
"""The camera presets of the View tab."""


@dataclass(frozen=True)
class ViewSettings:
    """Per-browser display settings.

    Attributes:
        lidar_coloring: ``"height"`` or ``"intensity"``.
        show_lidar, show_radar, show_rings: Layer toggles.
        lidar_point_size, radar_point_size: Point sizes in metres (perspective-attenuated; never
            more than keeps the nearest points legible from the camera:
            :class:`app.view.point_sizes.LegibleSizes`).
        velocity_range: m/s at which the radar map saturates (``+-``).
    """

    lidar_coloring: LidarColoring = "height"
    show_lidar: bool = True
    show_radar: bool = True
    show_rings: bool = True
    lidar_point_size: float = 0.1
    radar_point_size: float = 0.2
    velocity_range: float = 10.0


def lidar_colors(lidar: np.ndarray, ground_z: float, coloring: LidarColoring) -> np.ndarray:
    """``(N, 3)`` uint8 colours of LiDAR points ``(N, 4)`` for a colouring mode."""
    pts = np.asarray(lidar).reshape(-1, 4)
    if coloring == "intensity":
        return intensity_colors(pts[:, 3])
    return height_colors(pts[:, 2] - ground_z, *HEIGHT_RANGE)


def radar_colors(radar: np.ndarray, velocity_range: float) -> np.ndarray:
    """``(M, 3)`` uint8 colours of radar points ``(M, 7)`` by ``v_r_compensated``."""
    return velocity_colors(np.asarray(radar).reshape(-1, 7)[:, 5], velocity_range)


class SceneView:
    """Points, rings and ego marker of one browser (``client.scene``), under ``/scene``.

    Nodes: ``/scene/lidar``, ``/scene/radar`` (point clouds), ``/scene/rings`` (line segments),
    ``/scene/ring_labels/<r>``, ``/scene/ego`` (outline and heading arrow).
    """

    def __init__(self, scene: viser.SceneApi, settings: ViewSettings | None = None) -> None:
        self.scene = scene
        self.settings = settings or ViewSettings()
        self.ground_z = -LIDAR_HEIGHT
        self._lidar_pts = np.zeros((0, 4), np.float32)
        self._radar_pts = np.zeros((0, 7), np.float32)
        self._lidar: viser.PointCloudHandle | None = None
        self._radar: viser.PointCloudHandle | None = None
        self._rings: list[viser.SceneNodeHandle] = []
        self._ego: list[viser.SceneNodeHandle] = []
        self.sizes = LegibleSizes()
        """The clouds' point sizes, held legible from the browser's camera."""

    def show(self, lidar: np.ndarray, radar: np.ndarray, ground_z: float) -> None:
        """Draw a frame: ``lidar (N, 4)``, ``radar (M, 7)`` (LiDAR frame), ground at ``ground_z``."""
        self._lidar_pts = np.asarray(lidar, dtype=np.float32).reshape(-1, 4)
        self._radar_pts = np.asarray(radar, dtype=np.float32).reshape(-1, 7)
        s = self.settings
        self._lidar = self.scene.add_point_cloud(
            "/scene/lidar",
            self._lidar_pts[:, :3],
            lidar_colors(self._lidar_pts, ground_z, s.lidar_coloring),
            point_size=s.lidar_point_size,
            point_shape="square",
            precision="float32",
            visible=s.show_lidar,
        )
        self._radar = self.scene.add_point_cloud(
            "/scene/radar",
            self._radar_pts[:, :3],
            radar_colors(self._radar_pts, s.velocity_range),
            point_size=s.radar_point_size,
            point_shape="circle",
            precision="float32",
            visible=s.show_radar,
        )
        self.sizes.add(self._lidar, self._lidar_pts[:, :3], s.lidar_point_size)
        self.sizes.add(self._radar, self._radar_pts[:, :3], s.radar_point_size)
        if not self._rings or abs(ground_z - self.ground_z) > 1e-3:
            self.ground_z = ground_z
            self._draw_rings()

    def _draw_rings(self) -> None:
        for node in self._rings + self._ego:
            node.remove()
        gz = self.ground_z
        visible = self.settings.show_rings
        rings = self.scene.add_line_segments(
            "/scene/rings",
            ring_segments(gz),
            (120, 120, 130),
            thickness=1.0,
            thickness_units="screen",
            visible=visible,
        )
        self._rings = [rings]
        angle = np.deg2rad(35.0)
        for r in np.arange(RING_STEP, RING_MAX + 1e-9, RING_STEP):
            self._rings.append(
                self.scene.add_label(
                    f"/scene/ring_labels/{int(r)}",
                    f"{int(r)} m",
                    position=(r * np.cos(angle), r * np.sin(angle), gz + 0.05),
                    font_screen_scale=0.7,
                    anchor="center-center",
                    visible=visible,
                )
            )
        self._ego = [
            self.scene.add_line_segments(
                "/scene/ego",
                ego_segments(gz),
                (235, 235, 235),
                thickness=2.0,
                thickness_units="screen",
            )
        ]

    def apply(self, settings: ViewSettings) -> None:
        """Change display settings in place (colours, sizes, toggles)."""
        old, self.settings = self.settings, settings
        if self._lidar is not None:
            if settings.lidar_coloring != old.lidar_coloring:
                self._lidar.colors = lidar_colors(
                    self._lidar_pts, self.ground_z, settings.lidar_coloring
                )
            self.sizes.want(self._lidar, settings.lidar_point_size)
            self._lidar.visible = settings.show_lidar
        if self._radar is not None:
            if settings.velocity_range != old.velocity_range:
                self._radar.colors = radar_colors(self._radar_pts, settings.velocity_range)
            self.sizes.want(self._radar, settings.radar_point_size)
            self._radar.visible = settings.show_radar
        if settings.show_rings != old.show_rings:
            for node in self._rings:
                node.visible = settings.show_rings


LIDAR_COLORING_LABELS: dict[str, LidarColoring] = {"Height": "height", "Intensity": "intensity"}
"""Dropdown label -> LiDAR colouring."""


@dataclass(frozen=True)
class ViewPanel:
    """Handles of the "View" tab (built by :func:`build_view_panel`)."""

    lidar_coloring: viser.GuiDropdownHandle
    show_lidar: viser.GuiCheckboxHandle
    show_radar: viser.GuiCheckboxHandle
    show_rings: viser.GuiCheckboxHandle
    lidar_size: viser.GuiSliderHandle
    radar_size: viser.GuiSliderHandle
    velocity_range: viser.GuiSliderHandle
    radar_legend: viser.GuiImageHandle
    lidar_legend: viser.GuiImageHandle
    camera: viser.GuiButtonGroupHandle

    def settings(self) -> ViewSettings:
        """The settings the widgets currently hold."""
        return replace(
            ViewSettings(),
            lidar_coloring=LIDAR_COLORING_LABELS.get(self.lidar_coloring.value, "height"),
            show_lidar=bool(self.show_lidar.value),
            show_radar=bool(self.show_radar.value),
            show_rings=bool(self.show_rings.value),
            lidar_point_size=float(self.lidar_size.value),
            radar_point_size=float(self.radar_size.value),
            velocity_range=float(self.velocity_range.value),
        )

    def inputs(self) -> tuple[viser.GuiInputHandle, ...]:
        """Every input whose change alters :meth:`settings`."""
        return (
            self.lidar_coloring,
            self.show_lidar,
            self.show_radar,
            self.show_rings,
            self.lidar_size,
            self.radar_size,
            self.velocity_range,
        )

    def update_legends(self, settings: ViewSettings) -> None:
        """Redraw the legends for ``settings``."""
        self.radar_legend.image = velocity_legend(settings.velocity_range)
        self.lidar_legend.image = lidar_legend(settings.lidar_coloring)

    def wire(
        self,
        view: SceneView,
        client: viser.ClientHandle,
        lock: AbstractContextManager,
        ground_z: Callable[[], float],
        viewpoint: CameraViewpoint | None = None,
    ) -> None:
        """Apply every settings change to ``view`` (holding ``lock``, the browser's drawing lock)
        and the camera presets to ``client.camera`` (``ground_z()``: the ground on screen;
        ``viewpoint``: the camera panel, which gives the "Camera" preset and follows the radar
        colour scale). Leaving the "Camera" preset restores the browser's field of view."""
        saved_fov: list[float] = []

        def apply_settings(_: viser.GuiEvent) -> None:
            settings = self.settings()
            with lock, client.atomic():
                view.apply(settings)
                self.update_legends(settings)
                if viewpoint is not None:
                    viewpoint.set_velocity_range(settings.velocity_range)

        for handle in self.inputs():
            handle.on_update(apply_settings)

        @client.camera.on_update
        def _(camera: viser.CameraHandle) -> None:
            with lock:
                view.sizes.view_from(Eye.of(camera))

        @self.camera.on_click
        def _(event: viser.GuiEvent) -> None:
            ground = ground_z()
            choice = event.target.value
            if choice == "Camera":
                with lock:
                    pose = viewpoint.view_pose() if viewpoint is not None else None
                if pose is None:
                    return
                if not saved_fov:
                    saved_fov.append(float(client.camera.fov))
            else:
                pose = bev_pose(ground) if choice == "BEV" else chase_pose(ground)
                if saved_fov:
                    pose = replace(pose, fov=saved_fov.pop())
            apply_pose(client.camera, pose)


def lidar_legend(coloring: LidarColoring) -> np.ndarray:
    """The legend image of a LiDAR colouring mode."""
    return intensity_legend() if coloring == "intensity" else height_legend(*HEIGHT_RANGE)


CLASS_LEGEND = "Box colours"
"""The label of the class legend (:func:`build_view_panel`) before the classes' names."""


def build_view_panel(
    gui: viser.GuiApi, settings: ViewSettings | None = None, classes: Sequence[str] = VOD.names
) -> ViewPanel:
    """Add the View widgets to ``gui`` (in the current container) and return their handles;
    ``classes``: the served model's classes, whose colours the class legend shows (its label
    names them: "Box colours: Car, Pedestrian, Cyclist"; a PNG, so that its swatches are the
    colours of the boxes, :attr:`scenes.geometry.classes.ObjectClass.color`, exactly)."""
    s = settings or ViewSettings()
    coloring_label = next(k for k, v in LIDAR_COLORING_LABELS.items() if v == s.lidar_coloring)
    camera = gui.add_button_group(
        "Camera", PRESETS, hint="Viewpoints: bird's eye, behind the car, the frame's camera"
    )
    lidar_coloring = gui.add_dropdown(
        "LiDAR colour", tuple(LIDAR_COLORING_LABELS), initial_value=coloring_label
    )
    show_lidar = gui.add_checkbox("Show LiDAR", s.show_lidar)
    show_radar = gui.add_checkbox("Show radar", s.show_radar)
    show_rings = gui.add_checkbox("Range rings", s.show_rings, hint="Every 10 m")
    lidar_size = gui.add_slider("LiDAR size", 0.01, 0.3, 0.01, s.lidar_point_size)
    radar_size = gui.add_slider("Radar size", 0.05, 1.5, 0.05, s.radar_point_size)
    velocity_range = gui.add_slider(
        "Radar v scale", 1.0, 20.0, 1.0, s.velocity_range, hint="m/s at which colours saturate"
    )
    radar_legend = gui.add_image(
        velocity_legend(s.velocity_range), label="Radar colours: compensated radial velocity"
    )
    lidar_legend_handle = gui.add_image(lidar_legend(s.lidar_coloring), label="LiDAR colours")
    # PNG, not viser's JPEG for RGB: the swatches are the boxes' colours exactly, with sharp text
    legend = class_legend(classes)
    gui.add_image(legend, label=f"{CLASS_LEGEND}: {', '.join(classes)}", format="png")
    return ViewPanel(
        lidar_coloring=lidar_coloring,
        show_lidar=show_lidar,
        show_radar=show_radar,
        show_rings=show_rings,
        lidar_size=lidar_size,
        radar_size=radar_size,
        velocity_range=velocity_range,
        radar_legend=radar_legend,
        lidar_legend=lidar_legend_handle,
        camera=camera,
    )
