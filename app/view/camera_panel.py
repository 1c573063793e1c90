"""The camera panel of one browser: the frame's camera image with the boxes projected into it.

A floating window of its own (viser's ``gui.add_panel``, placed at the bottom left of the 3D
view; the person can move, dock or minimise it), so the image stays in sight whichever tab of
the control panel is open. It shows:

- the frame's image (``image_2/<id>.jpg``, :attr:`scenes.frame.Sample.image`) scaled to
  :data:`app.view.camera_image.DISPLAY_WIDTH` pixels;
- box layers drawn as 3D wireframes (:class:`app.view.camera_image.BoxLayer`), in the order of
  :data:`LAYER_ORDER`: on a frame with commands the other annotations (``others``: thin, class
  colours; the Query tab's *Other annotations* hides them) and the referent of the command in
  play (``gt``: green, labelled ``referent``), elsewhere the sample's own boxes (``gt``: thin,
  green, unlabelled), then the current answer (class
  colours, score labels) and the annotation draft on top (near-white, the selected box gold);
  extensions set their own layers by name (:meth:`CameraPanel.set_layer`);
- optionally (*LiDAR on image*, *Radar on image*) the LiDAR points coloured by depth (red near,
  violet far) and the radar points by compensated radial velocity (the 3D view's map and scale).

A frame without an image shows a note saying so; an image that cannot be read (missing, corrupt,
truncated) shows the reader's message naming the file, and the rest of the frame works. An image
whose size puts P2's principal point far from its centre gets a warning line naming the file.

Not thread-safe by itself: its owner (:class:`app.session.ClientSession`) holds the browser's
drawing lock while calling it (:meth:`CameraPanel.wire` takes that lock for the panel's own
checkboxes).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path

import numpy as np
import viser

from app.engine import Predictions
from app.serving.ground_truth import FrameObjects
from app.text import md_text
from app.view.camera_image import (
    LIDAR_DOT,
    RADAR_DOT,
    BoxLayer,
    CameraImage,
    compose,
    display_image,
    lidar_overlay,
    paint_points,
    radar_overlay,
)
from app.view.colors import GT_COLOR, class_color
from app.view.scene_view import CameraPose, camera_view_pose
from scenes.frame import Sample
from scenes.frame.image import check_principal_point

log = logging.getLogger(__name__)

LAYER_ORDER = ("others", "gt", "pred", "draft")
"""Layers drawn bottom to top; other names are drawn after these, in the order they were set."""

PANEL_WIDTH = 560
"""Initial width (px) of the floating camera window."""

JPEG_QUALITY = 85
"""Quality of the JPEG sent to the browser."""

MAX_PREDICTED = 30
"""Predicted boxes drawn at most (the best scores; the 3D view draws them all)."""

MAX_LABELLED = 10
"""Predicted boxes labelled at most (the best scores), so that labels do not hide the image."""


def gt_layer(sample: Sample) -> BoxLayer:
    """The sample's ground truth: thin green wireframes, no labels."""
    k = len(sample.boxes)
    return BoxLayer(sample.boxes, (GT_COLOR,) * k, ("",) * k, width=2)


def object_layers(objects: FrameObjects) -> tuple[BoxLayer, BoxLayer]:
    """``(gt, others)`` of a frame with commands: its referents green, 3 px, labelled
    ``"referent"``; the other labelled objects thin in their class colours, unlabelled."""
    mask = np.asarray(objects.referent, dtype=bool)
    k = int(mask.sum())
    classes = [c for c, ref in zip(objects.classes, mask, strict=True) if not ref]
    return (
        BoxLayer(objects.boxes[mask], (GT_COLOR,) * k, ("referent",) * k, width=3),
        BoxLayer(
            objects.boxes[~mask], tuple(class_color(c) for c in classes), ("",) * len(classes)
        ),
    )


def prediction_layer(pred: Predictions) -> BoxLayer:
    """The best :data:`MAX_PREDICTED` boxes of an answer in their class colours, the best
    :data:`MAX_LABELLED` labelled with class and score (``"Car 0.87"``)."""
    k = min(len(pred.boxes), MAX_PREDICTED)
    colors = tuple(class_color(c) for c in pred.classes[:k])
    labels = tuple(
        f"{c} {float(s):.2f}" if i < MAX_LABELLED else ""
        for i, (c, s) in enumerate(zip(pred.classes[:k], pred.scores[:k], strict=True))
    )
    return BoxLayer(np.asarray(pred.boxes)[:k], colors, labels, width=3)


def image_note(sample: Sample) -> str:
    """The note shown for a frame without a camera image (markdown, the id escaped)."""
    return (
        f"*No camera image for sample {md_text(sample.sample_id)}* (the root has no "
        f"training/image\\_2/{md_text(sample.sample_id)}.jpg); the boxes are in the 3D view."
    )


class CameraPanel:
    """One browser's camera window (see the module docstring).

    Args:
        gui: The browser's GUI API (``client.gui``).
        velocity_range: m/s at which the radar overlay's colours saturate.
    """

    def __init__(self, gui: viser.GuiApi, velocity_range: float = 10.0) -> None:
        self.velocity_range = float(velocity_range)
        self.window = gui.add_panel()
        with self.window.add_tab("Camera", icon=viser.Icon.CAMERA):
            self.note = gui.add_markdown("*No frame yet.*")
            self.image = gui.add_image(
                np.zeros((8, 8, 3), np.uint8), format="jpeg", jpeg_quality=JPEG_QUALITY
            )
            self.image.visible = False
            self.show_lidar = gui.add_checkbox(
                "LiDAR on image", False, hint="LiDAR points coloured by depth: red near, violet far"
            )
            self.show_radar = gui.add_checkbox(
                "Radar on image",
                False,
                hint="Radar points coloured by compensated radial velocity: blue approaches, "
                "red recedes (the View tab's scale)",
            )
        self.window.float(x=12, y=-12, width=PANEL_WIDTH)
        self.sample: Sample | None = None
        self.camera: CameraImage | None = None
        """The frame's image at display size (None: the frame has none, or it is unreadable)."""
        self.error: str | None = None
        """Why the frame's image could not be shown (None: it is shown, or there is none)."""
        self._layers: dict[str, BoxLayer] = {}
        self._hidden: set[str] = set()
        self._background: np.ndarray | None = None
        self._background_key: tuple | None = None
        self.draws = 0
        """Images sent so far (each redraw sends one)."""
        self.last_draw_ms = 0.0
        """Milliseconds the last redraw took (projection, drawing, JPEG encoding)."""

    # ------------------------------------------------------------------ state

    def show_frame(self, sample: Sample, objects: FrameObjects | None = None) -> None:
        """Show ``sample``'s image (decoded on first use, scaled once) with its ground truth
        (layer ``gt``; with ``objects``, those of a frame with commands: :func:`object_layers`)
        and no answer (layer ``pred`` removed); the other layers are kept (their owners replace
        them)."""
        self.sample = sample
        self._layers.pop("pred", None)
        self._layers.pop("others", None)
        self._layers["gt"] = gt_layer(sample)
        if objects is not None:
            self._layers["gt"], self._layers["others"] = object_layers(objects)
        self.camera, self.error = None, None
        self._background, self._background_key = None, None
        warning = None
        try:
            image = sample.image
        except ValueError as exc:  # scenes.frame.image.ImageError names the file
            self.error = str(exc)
            log.warning("camera image of %s: %s", sample.sample_id, exc)
        else:
            if image is not None:
                self.camera = display_image(image, sample.calib)
                principal = (float(sample.calib.P2[0, 2]), float(sample.calib.P2[1, 2]))
                warning = check_principal_point(
                    self.camera.full_size, principal, str(sample.image_path)
                )
        if self.error is not None:
            self.note.content = (
                f"**The camera image cannot be shown:** {md_text(self.error)}  \n"
                "The rest of the frame works."
            )
        elif self.camera is None:
            self.note.content = image_note(sample)
        else:
            width, height = self.camera.full_size
            name = Path(sample.image_path).name if sample.image_path is not None else ""
            self.note.content = f"{md_text(name)} · {width} x {height}" + (
                f"  \n**Warning:** {md_text(warning)}" if warning else ""
            )
        self.image.visible = self.camera is not None
        self.redraw()

    def show_objects(self, objects: FrameObjects) -> None:
        """Draw a frame with commands' referent and other annotations (:func:`object_layers`)."""
        gt, others = object_layers(objects)
        self.set_layer("others", others)
        self.set_layer("gt", gt)

    def show_gt(self, ground_truth: bool, others: bool) -> None:
        """The Query tab's *Ground truth* (every layer of labelled boxes) and *Other
        annotations* (the layer ``others``)."""
        self.set_layer_visible("gt", ground_truth)
        self.set_layer_visible("others", ground_truth and others)

    def show_predictions(self, pred: Predictions) -> None:
        """Draw an answer's boxes (layer ``pred``, :func:`prediction_layer`)."""
        self.set_layer("pred", prediction_layer(pred))

    def view_pose(self) -> CameraPose | None:
        """The 3D view's "Camera" preset for the frame shown: the camera's pose and vertical
        field of view (from the image's height; P2's principal point without an image)."""
        if self.sample is None:
            return None
        height = self.camera.full_size[1] if self.camera is not None else None
        return camera_view_pose(self.sample.calib, height)

    def set_layer(self, name: str, layer: BoxLayer | None) -> None:
        """Replace (None: remove) the box layer ``name``; redraws only when it changed."""
        old = self._layers.get(name)
        if layer is None or not len(layer.boxes):
            if old is None or not len(old.boxes):
                self._layers.pop(name, None)
                return
            self._layers.pop(name, None)
        elif layer.same_as(old):
            return
        else:
            self._layers[name] = layer
        if name not in self._hidden:
            self.redraw()

    def layer(self, name: str) -> BoxLayer | None:
        """The box layer ``name``, if set."""
        return self._layers.get(name)

    def set_layer_visible(self, name: str, visible: bool) -> None:
        """Show or hide the layer ``name`` (kept while hidden)."""
        hidden = name in self._hidden
        if hidden == (not visible):
            return
        if visible:
            self._hidden.discard(name)
        else:
            self._hidden.add(name)
        if name in self._layers:
            self.redraw()

    def set_velocity_range(self, velocity_range: float) -> None:
        """The radar overlay's saturation (m/s), as the View tab's *Radar v scale*."""
        if float(velocity_range) != self.velocity_range:
            self.velocity_range = float(velocity_range)
            if self.show_radar.value:
                self.redraw()

    def visible_layers(self) -> list[BoxLayer]:
        """The layers drawn, bottom to top."""
        names = [n for n in LAYER_ORDER if n in self._layers]
        names += [n for n in self._layers if n not in LAYER_ORDER]
        return [self._layers[n] for n in names if n not in self._hidden]

    # ------------------------------------------------------------------ drawing

    def _points_background(self) -> np.ndarray:
        """The scaled image with the chosen point overlays painted in (cached per frame and
        overlay settings)."""
        assert self.camera is not None and self.sample is not None
        lidar, radar = bool(self.show_lidar.value), bool(self.show_radar.value)
        key = (id(self.camera), lidar, radar, self.velocity_range if radar else None)
        if self._background is not None and self._background_key == key:
            return self._background
        background = self.camera.image
        if lidar or radar:
            background = background.copy()
            calib, size = self.camera.calib, self.camera.size
            if lidar:
                paint_points(background, *lidar_overlay(self.sample.lidar, calib, size), LIDAR_DOT)
            if radar:
                uv, colors = radar_overlay(self.sample.radar, calib, size, self.velocity_range)
                paint_points(background, uv, colors, RADAR_DOT)
        self._background, self._background_key = background, key
        return background

    def render(self) -> np.ndarray | None:
        """The image with the overlays, as it would be sent (None without an image)."""
        if self.camera is None:
            return None
        return compose(self._points_background(), self.camera.calib, self.visible_layers())

    def redraw(self) -> None:
        """Draw the overlays and send the image (nothing without an image)."""
        if self.camera is None:
            return
        start = time.perf_counter()
        picture = self.render()
        assert picture is not None
        self.image.image = picture
        self.draws += 1
        self.last_draw_ms = (time.perf_counter() - start) * 1000.0

    def wire(self, lock: AbstractContextManager, report: Callable[[BaseException], None]) -> None:
        """Redraw when the point overlays are switched (holding ``lock``, the browser's drawing
        lock); an error goes to ``report``."""

        def redraw(event: viser.GuiEvent) -> None:
            if event.client is None:
                return
            try:
                with lock:
                    self.redraw()
            except Exception as exc:
                report(exc)

        self.show_lidar.on_update(redraw)
        self.show_radar.on_update(redraw)
