"""The annotation draft in the viewer: draft boxes, the selected box and its transform gizmo, and
the geometry of a ground click.

Per browser (``client.scene``), under ``/annotate``:

- ``/annotate/boxes/edges`` and ``/annotate/boxes/labels/<i>``: the draft boxes that are not
  selected, drawn as :mod:`app.view.boxes_view` draws boxes (12 edges and a heading tick each) in
  :data:`DRAFT_COLOR`, a near-white that no class, ground-truth or radar colour uses, with a
  ``"#2 Car"`` label (the box's number in the panel's list).
- ``/annotate/gizmo``: viser's transform gizmo, restricted to what a box on the ground needs: the
  X and Y arrows, the XY-plane square and the ring about Z (yaw); no Z arrow, no roll or pitch
  ring (``active_axes=(True, True, False)``; the gizmo has no scale handle in viser 1.1.1). It sits
  at the selected box's centre, turned by its yaw, so its arrows run along and across the box.
- ``/annotate/gizmo/selected/...``: the selected box, thicker and in :data:`SELECTED_COLOR`, as a
  child of the gizmo in the gizmo's frame: dragging the gizmo moves and turns the box in the
  browser at once, with no round trip to the server.
- ``/annotate/ready/...``: the ready-made boxes (the frame's label_2 objects not in the draft,
  offered on roots without prompts), thin, in :data:`READY_COLOR`, labelled ``"+ Car"``: a click
  on one adds it to the draft.

The camera panel gets the draft as its ``draft`` layer (:func:`draft_layer`): the same colours
and ``"#2 Car"`` labels.

Ground clicks: viser reports a click as a ray (origin and direction, world = LiDAR frame);
:func:`ground_hit` intersects it with the horizontal plane ``z = ground_z``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import viser

from annotate import Draft
from app.view.boxes_view import BoxesView, BoxStyle
from app.view.camera_image import BoxLayer
from scenes.geometry.boxes import points_in_boxes

DRAFT_COLOR = (235, 235, 255)
"""Draft boxes that are not selected (near-white: unlike every class, GT and radar colour)."""

SELECTED_COLOR = (255, 215, 0)
"""The selected draft box (gold)."""

DRAFT_STYLE = BoxStyle(thickness=2.5, color=DRAFT_COLOR, label_anchor="bottom-center")
"""How unselected draft boxes are drawn."""

SELECTED_STYLE = BoxStyle(thickness=4.5, color=SELECTED_COLOR, label_anchor="bottom-center")
"""How the selected draft box is drawn."""

READY_COLOR = (190, 150, 255)
"""Ready-made boxes (lavender: unlike every class, GT, draft and radar colour)."""

READY_STYLE = BoxStyle(
    thickness=1.5, color=READY_COLOR, label_anchor="bottom-center", label_lift=0.1, max_labels=40
)
"""How ready-made boxes are drawn."""

PREFIX = "/annotate"
"""Scene-tree prefix of every node of the annotation mode."""

MAX_CLICK_RANGE = 150.0
"""Ground points farther than this (m, BEV) from the sensor are not taken as a click on the
ground (a ray grazing the horizon)."""

SELECT_MARGIN = 0.2
"""A ground click within this distance (m) of a draft box's footprint selects that box."""


def ground_hit(
    ray_origin: Sequence[float],
    ray_direction: Sequence[float],
    ground_z: float,
    max_range: float = MAX_CLICK_RANGE,
) -> tuple[float, float] | None:
    """Where a click ray meets the ground plane ``z = ground_z`` (LiDAR frame).

    Args:
        ray_origin: ``(3,)`` camera position, LiDAR frame.
        ray_direction: ``(3,)`` direction through the clicked pixel (any length).
        ground_z: Ground height (m).
        max_range: Hits farther than this BEV distance from the origin of the LiDAR frame are
            refused.

    Returns:
        ``(x, y)`` of the hit, or None when the ray does not go down to the ground in front of
        the camera, or hits it beyond ``max_range``.
    """
    o = np.asarray(ray_origin, dtype=np.float64).reshape(3)
    d = np.asarray(ray_direction, dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))) or abs(d[2]) < 1e-9:
        return None
    t = (ground_z - o[2]) / d[2]
    if t <= 0:
        return None
    x, y = float(o[0] + t * d[0]), float(o[1] + t * d[1])
    if math.hypot(x, y) > max_range:
        return None
    return x, y


def box_at(boxes: np.ndarray, x: float, y: float, margin: float = SELECT_MARGIN) -> int | None:
    """The box whose bird's-eye-view footprint (grown by ``margin`` per side) holds ``(x, y)``.

    Args:
        boxes: ``(K, 7)`` LiDAR frame.

    Returns:
        Its index (the one with the nearest centre when several hold the point), or None.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if not len(b):
        return None
    grown = b.copy()
    grown[:, 3:5] += 2.0 * margin
    grown[:, 2], grown[:, 5] = 0.0, 1.0  # a prism: heights play no part
    inside = points_in_boxes(np.array([[x, y, 0.0]]), grown)[0]
    if not inside.any():
        return None
    candidates = np.nonzero(inside)[0]
    dist = np.hypot(b[candidates, 0] - x, b[candidates, 1] - y)
    return int(candidates[int(np.argmin(dist))])


def yaw_to_wxyz(yaw: float) -> tuple[float, float, float, float]:
    """Quaternion ``(w, x, y, z)`` of a rotation by ``yaw`` about +z."""
    half = 0.5 * float(yaw)
    return (math.cos(half), 0.0, 0.0, math.sin(half))


def wxyz_to_yaw(wxyz: Sequence[float]) -> float:
    """The heading (rotation about +z, radians in ``(-pi, pi]``) of a quaternion ``(w, x, y, z)``.

    Computed from the rotated x axis projected on the ground, so a quaternion with a little roll
    or pitch (numerical noise from the browser) still gives its heading.
    """
    w, x, y, z = (float(v) for v in wxyz)
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if norm < 1e-12:
        return 0.0
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r10 = 2.0 * (x * y + w * z)
    return math.atan2(r10, r00)


def screen_axes(
    camera_position: Sequence[float], look_at: Sequence[float]
) -> tuple[tuple[float, float], tuple[float, float]]:
    """The ground directions that the arrow keys move a box along: ``(forward, right)`` unit
    vectors (LiDAR frame x, y), each the LiDAR axis (+-x or +-y) closest to what points up and
    right on the screen of a camera at ``camera_position`` looking at ``look_at``.

    Snapping to the axes makes steps predictable (0.1 m along x is 0.1 m along x). A camera
    looking straight down has no forward direction on the ground: +x is taken (the sensor's
    heading).
    """
    d = (
        np.asarray(look_at, dtype=np.float64)[:2]
        - np.asarray(camera_position, dtype=np.float64)[:2]
    )
    if not np.all(np.isfinite(d)) or float(np.hypot(*d)) < 1e-6:
        d = np.array([1.0, 0.0])
    along_x = abs(d[0]) >= abs(d[1])
    forward = (float(np.sign(d[0])), 0.0) if along_x else (0.0, float(np.sign(d[1])))
    right = (forward[1], -forward[0])  # turned 90 degrees clockwise seen from above
    return forward, right


def gizmo_scale(box: Sequence[float]) -> float:
    """Size of the gizmo for a box (m): its arrows reach past the box's front (>= 2 m)."""
    return max(2.0, 0.9 * float(max(box[3], box[4])))


def box_tag(index: int, cls: str) -> str:
    """Label of draft box ``index`` (0-based) in the scene and the panel: ``"#2 Car"``."""
    return f"#{index + 1} {cls}"


def draft_layer(draft: Draft, selected_id: int | None, visible: bool = True) -> BoxLayer | None:
    """The draft as the camera panel's layer (None when hidden or empty): near-white boxes, the
    selected one gold, each labelled ``"#2 Car"``."""
    if not visible or not draft.boxes:
        return None
    colors = tuple(SELECTED_COLOR if b.box_id == selected_id else DRAFT_COLOR for b in draft.boxes)
    tags = tuple(box_tag(i, b.cls) for i, b in enumerate(draft.boxes))
    return BoxLayer(draft.box_array, colors, tags, width=3)


class DraftView:
    """The draft boxes and the gizmo of one browser (see the module docstring).

    Not thread-safe by itself: the owner (:class:`app.annotate_tab.panel.AnnotationPanel`) holds
    the session's lock while calling it.

    Args:
        scene: The browser's scene API (``client.scene``).
    """

    def __init__(self, scene: viser.SceneApi) -> None:
        self.scene = scene
        self.others = BoxesView(scene, f"{PREFIX}/boxes", DRAFT_STYLE)
        self.gizmo = scene.add_transform_controls(
            f"{PREFIX}/gizmo",
            scale=2.0,
            active_axes=(True, True, False),
            depth_test=False,
            visible=False,
        )
        self.selected = BoxesView(scene, f"{PREFIX}/gizmo/selected", SELECTED_STYLE)
        self.ready = BoxesView(scene, f"{PREFIX}/ready", READY_STYLE)
        self.gizmo_box_id: int | None = None
        """The draft box the gizmo holds (None: hidden)."""

    def show(self, draft: Draft, selected_id: int | None, visible: bool = True) -> None:
        """Draw ``draft`` with box ``selected_id`` (or none) selected; ``visible=False`` hides
        everything (the draft belongs to another frame)."""
        boxes = draft.box_array
        tags = [box_tag(i, b.cls) for i, b in enumerate(draft.boxes)]
        keep = [i for i, b in enumerate(draft.boxes) if b.box_id != selected_id]
        if visible and keep:
            self.others.show(
                boxes[keep], [draft.boxes[i].cls for i in keep], [tags[i] for i in keep]
            )
        else:
            self.others.clear()
        if not visible or selected_id is None or selected_id not in draft.box_ids:
            self.selected.clear()
            self.gizmo.visible = False
            self.gizmo_box_id = None
            return
        index = draft.index_of(selected_id)
        box = boxes[index]
        local = np.array([[0.0, 0.0, 0.0, box[3], box[4], box[5], 0.0]])
        self.gizmo.position = (float(box[0]), float(box[1]), float(box[2]))
        self.gizmo.wxyz = yaw_to_wxyz(float(box[6]))
        self.gizmo.scale = gizmo_scale(box)
        self.selected.show(local, [draft.boxes[index].cls], [f"{tags[index]} (selected)"])
        self.gizmo.visible = True
        self.gizmo_box_id = selected_id

    def show_ready(self, boxes: np.ndarray, classes: Sequence[str]) -> None:
        """Draw the ready-made boxes ``(R, 7)`` (none: remove them)."""
        if len(boxes):
            self.ready.show(boxes, classes, [f"+ {c}" for c in classes])
        else:
            self.ready.clear()

    def clear(self) -> None:
        """Remove the boxes and hide the gizmo."""
        self.ready.clear()
        self.others.clear()
        self.selected.clear()
        self.gizmo.visible = False
        self.gizmo_box_id = None
