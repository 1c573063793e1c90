"""3D boxes in the viewer: predicted boxes (class colours, score labels) and ground truth.

Boxes are ``(K, 7)`` ``x, y, z, l, w, h, yaw`` in the LiDAR frame (z at the geometric centre, yaw
counter-clockwise about +z from +x), the viewer's world frame. All edges of one set go into
**one** ``add_line_segments`` node (one draw call; viser's wireframe boxes would show triangle
diagonals): 12 edges per box plus a *heading tick* from the centre of the top face to the middle of
its front edge, so the heading reads in the bird's-eye view too. Each box gets one label node.

Styles: predictions are drawn 3 px wide in their class colour with a label above the box
(``"Car 0.87"``, plus ``"IoU 0.64"`` against the best-matching labelled object when the frame has
labelled objects); the ground truth (:class:`GroundTruthView`) is every labelled object of the
frame (:class:`app.serving.ground_truth.FrameObjects`) drawn thinner in its class colour with a
``"#2 Car"`` label hanging below the top face, so that a prediction lying on it stays readable,
except the referents of the frame's prompt (or of the command in play, :mod:`app.serving.frame_commands`),
drawn apart: thick in :data:`app.view.colors.GT_COLOR`, labelled ``"#3 Car (referent)"`` above. The
objects that are not referents are shown or hidden as one group.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import viser

from app.serving.ground_truth import FrameObjects
from app.view.colors import GT_COLOR, RGB, class_color
from scenes.geometry.boxes import box_corners, iou3d

BOX_EDGES: tuple[tuple[int, int], ...] = (
    (0, 1),
    (1, 2),
    (2, 3),
    (3, 0),
    (4, 5),
    (5, 6),
    (6, 7),
    (7, 4),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
)
"""Corner index pairs of the 12 edges, for the corner order of :func:`scenes.geometry.boxes.box_corners`
(bottom FL, RL, RR, FR, then top FL, RL, RR, FR)."""

SEGMENTS_PER_BOX = len(BOX_EDGES) + 1
"""12 edges and the heading tick."""


def box_segments(boxes: np.ndarray) -> np.ndarray:
    """Line segments of boxes: per box its 12 edges, then its heading tick.

    Args:
        boxes: ``(K, 7)`` LiDAR frame.

    Returns:
        ``(13 K, 2, 3)`` float32 segment end points, LiDAR frame; box ``k`` owns rows
        ``13 k .. 13 k + 12``, the last of which is the tick from the top face's centre to the
        midpoint of its front edge (corners 4 and 7).
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(b) == 0:
        return np.zeros((0, 2, 3), dtype=np.float32)
    corners = box_corners(b)  # (K, 8, 3)
    edges = np.asarray(BOX_EDGES)
    segs = corners[:, edges]  # (K, 12, 2, 3)
    top_centre = b[:, :3].copy()
    top_centre[:, 2] += b[:, 5] / 2.0
    front_mid = (corners[:, 4] + corners[:, 7]) / 2.0
    tick = np.stack([top_centre, front_mid], axis=1)[:, None]  # (K, 1, 2, 3)
    return np.concatenate([segs, tick], axis=1).reshape(-1, 2, 3).astype(np.float32)


def best_iou(predicted: np.ndarray, ground_truth: np.ndarray) -> np.ndarray:
    """3D IoU of each predicted box with its best-matching ground-truth box.

    Args:
        predicted: ``(K, 7)`` boxes.
        ground_truth: ``(G, 7)`` boxes.

    Returns:
        ``(K,)`` float64 in ``[0, 1]``; NaN for every box when ``G == 0`` (no ground truth).
    """
    pred = np.asarray(predicted, dtype=np.float64).reshape(-1, 7)
    gt = np.asarray(ground_truth, dtype=np.float64).reshape(-1, 7)
    if len(gt) == 0:
        return np.full(len(pred), np.nan)
    if len(pred) == 0:
        return np.zeros(0)
    return np.asarray(iou3d(pred, gt)).max(axis=1)


def box_label(cls: str, score: float | None = None, iou: float | None = None) -> str:
    """Label text of one box: ``"Car 0.87"``, ``"Car 0.87 | IoU 0.64"`` or ``"GT Car"``.

    Args:
        cls: Class name.
        score: Confidence in ``[0, 1]``; None for a ground-truth box.
        iou: Best IoU with the ground truth; None or NaN to leave it out.
    """
    if score is None:
        return f"GT {cls}"
    text = f"{cls} {score:.2f}"
    if iou is not None and np.isfinite(iou):
        text += f" | IoU {iou:.2f}"
    return text


@dataclass(frozen=True)
class BoxStyle:
    """How one set of boxes is drawn.

    Attributes:
        thickness: Line width in screen pixels.
        color: Fixed colour of every box, or None to colour by class (:func:`app.view.colors.class_color`).
        label_anchor: viser label anchor; ``"bottom-center"`` puts the text above the top face.
        label_lift: Metres between the top face and the label's anchor point.
        max_labels: Labels drawn at most (the first boxes, i.e. the best scores).
    """

    thickness: float = 3.0
    color: RGB | None = None
    label_anchor: str = "bottom-center"
    label_lift: float = 0.25
    max_labels: int = 20


PRED_STYLE = BoxStyle()
"""Predicted boxes."""

GT_STYLE = BoxStyle(thickness=4.0, color=GT_COLOR, max_labels=0)
"""The referents of the frame's prompt (or of the command in play) among the ground truth: thick
and in :data:`app.view.colors.GT_COLOR`, their label (``"#3 Car (referent)"``) above the box."""

OBJECT_STYLE = BoxStyle(thickness=1.5, label_anchor="top-center", label_lift=-0.1)
"""Every labelled object of the frame (ground truth): thin, in its class colour, its label
(``"#2 Car"``) hanging below the top face so that a prediction lying on it stays readable."""


def segment_colors(classes: Sequence[str], style: BoxStyle) -> np.ndarray:
    """Per-end-point colours ``(13 K, 2, 3)`` uint8 for :func:`box_segments` of ``K`` boxes."""
    rgb = np.array(
        [style.color if style.color is not None else class_color(c) for c in classes],
        dtype=np.uint8,
    ).reshape(-1, 3)
    return np.repeat(rgb, SEGMENTS_PER_BOX * 2, axis=0).reshape(-1, 2, 3)


class BoxesView:
    """One set of boxes (edges + labels) under a scene-tree prefix, e.g. ``/pred``.

    Nodes: ``<prefix>/edges`` (line segments) and ``<prefix>/labels/<i>``. :meth:`show` replaces
    the previous set. Not thread-safe by itself: the owner (:class:`app.session.ClientSession`)
    serialises calls.

    Args:
        scene: The scene API to draw into (``client.scene`` for per-browser boxes).
        prefix: Scene-tree prefix of the nodes.
        style: Line width, colours, label placement.
    """

    def __init__(self, scene: viser.SceneApi, prefix: str, style: BoxStyle) -> None:
        self.scene = scene
        self.prefix = prefix
        self.style = style
        self._edges: viser.LineSegmentsHandle | None = None
        self._labels: list[viser.LabelHandle] = []
        self._visible = True
        self.count = 0

    @property
    def edges_name(self) -> str:
        """Scene-tree name of the edge node."""
        return f"{self.prefix}/edges"

    def label_name(self, index: int) -> str:
        """Scene-tree name of the label of box ``index``."""
        return f"{self.prefix}/labels/{index}"

    def clear(self) -> None:
        """Remove every node of this set."""
        if self._edges is not None:
            self._edges.remove()
            self._edges = None
        for label in self._labels:
            label.remove()
        self._labels = []
        self.count = 0

    def show(self, boxes: np.ndarray, classes: Sequence[str], labels: Sequence[str]) -> None:
        """Replace the drawn set.

        Args:
            boxes: ``(K, 7)`` LiDAR frame.
            classes: ``K`` class names (colours).
            labels: ``K`` label texts (only the first ``style.max_labels`` are drawn).
        """
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
        if not len(b) == len(classes) == len(labels):
            raise ValueError(
                f"BoxesView.show: {len(b)} boxes, {len(classes)} classes, {len(labels)} labels"
            )
        self.clear()
        if len(b) == 0:
            return
        self._edges = self.scene.add_line_segments(
            self.edges_name,
            box_segments(b),
            segment_colors(classes, self.style),
            thickness=self.style.thickness,
            thickness_units="screen",
            visible=self._visible,
        )
        for i, (box, text) in enumerate(zip(b[: self.style.max_labels], labels, strict=False)):
            top = (box[0], box[1], box[2] + box[5] / 2.0 + self.style.label_lift)
            self._labels.append(
                self.scene.add_label(
                    self.label_name(i),
                    text,
                    position=top,
                    anchor=self.style.label_anchor,  # type: ignore[arg-type]
                    font_screen_scale=0.8,
                    visible=self._visible,
                )
            )
        self.count = len(b)

    @property
    def visible(self) -> bool:
        return self._visible

    @visible.setter
    def visible(self, value: bool) -> None:
        self._visible = bool(value)
        if self._edges is not None:
            self._edges.visible = self._visible
        for label in self._labels:
            label.visible = self._visible


def _applied_flag(attribute: str, doc: str) -> property:
    """A boolean property kept in ``attribute`` whose every assignment re-draws the layer's
    visibility (the owner's ``_apply``)."""

    def get(self: GroundTruthView) -> bool:
        return getattr(self, attribute)

    def set_(self: GroundTruthView, value: bool) -> None:
        setattr(self, attribute, bool(value))
        self._apply()

    return property(get, set_, doc=doc)


class GroundTruthView:
    """The *Ground truth* layer: every labelled object (``<prefix>/edges``: thin, class colours),
    the frame's referents over theirs (``<prefix>/referents/edges``: thick,
    :data:`app.view.colors.GT_COLOR`) and every object's label (``<prefix>/labels/<i>``, numbered from the nearest,
    ``"#3 Car (referent)"`` for a referent, at most :data:`OBJECT_STYLE`'s ``max_labels`` of the
    others). :attr:`visible` shows or hides it all (*Ground truth*), :attr:`others_visible` the
    objects that are not referents, edges and labels, as one group (*Other annotations*). Not
    thread-safe by itself (the session serialises calls).

    Args:
        scene: The scene API to draw into.
        prefix: Scene-tree prefix.
    """

    def __init__(self, scene: viser.SceneApi, prefix: str = "/gt") -> None:
        self.scene = scene
        self.prefix = prefix
        self.objects = BoxesView(scene, prefix, replace(OBJECT_STYLE, max_labels=0))
        """The thin edges of every object (a referent's lie under its thick ones: hiding these
        hides the others and leaves the referents as they look)."""
        self.referents = BoxesView(scene, f"{prefix}/referents", GT_STYLE)
        self._labels: list[tuple[viser.LabelHandle, bool]] = []
        """Each label drawn and whether its object is a referent."""
        self._visible = True
        self._others = True

    def show(self, objects: FrameObjects) -> None:
        """Draw the frame's ``objects`` (replacing the previous frame's)."""
        mask = np.asarray(objects.referent, dtype=bool)
        self.objects.show(objects.boxes, objects.classes, [""] * len(objects))
        classes = [c for c, ref in zip(objects.classes, mask, strict=True) if ref]
        self.referents.show(objects.boxes[mask], classes, [""] * len(classes))
        for label, _ in self._labels:
            label.remove()
        self._labels = []
        texts = objects.labels()
        for i, (box, text, referent) in enumerate(zip(objects.boxes, texts, mask, strict=True)):
            if not referent and i >= OBJECT_STYLE.max_labels:
                continue
            style = GT_STYLE if referent else OBJECT_STYLE
            top = (box[0], box[1], box[2] + box[5] / 2.0 + style.label_lift)
            label = self.scene.add_label(
                f"{self.prefix}/labels/{i}",
                text,
                position=top,
                anchor=style.label_anchor,  # type: ignore[arg-type]
                font_screen_scale=0.9 if referent else 0.8,
                visible=self._visible and (referent or self._others),
            )
            self._labels.append((label, bool(referent)))
        self._apply()

    def _apply(self) -> None:
        self.referents.visible = self._visible
        self.objects.visible = self._visible and self._others
        for label, referent in self._labels:
            label.visible = self._visible and (referent or self._others)

    visible = _applied_flag("_visible", "Whether the layer is shown (*Ground truth*).")
    others_visible = _applied_flag(
        "_others", "Whether the objects that are not referents are shown (when :attr:`visible`)."
    )
