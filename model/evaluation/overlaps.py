"""Overlaps of the VoD protocol (:mod:`model.evaluation.protocol`), detections x ground truth in
the camera frame: 2D image IoU, exact BEV and 3D IoU."""

from __future__ import annotations

import numpy as np

from model.evaluation.protocol import FrameObjects, Metric
from scenes.geometry.boxes import bev_iou, iou3d


def image_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """2D IoU ``(K1, K2)`` of image boxes ``a (K1, 4)`` and ``b (K2, 4)`` (left, top, right,
    bottom; pixels, no +1)."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    iw = np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0])
    ih = np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1])
    inter = np.where((iw > 0) & (ih > 0), iw * ih, 0.0)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(inter > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def image_intersection_over_first(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over the area of ``a`` ``(K1, K2)`` (the don't-care test)."""
    iw = np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0])
    ih = np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1])
    inter = np.where((iw > 0) & (ih > 0), iw * ih, 0.0)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    return np.where(inter > 0, inter / np.where(area_a > 0, area_a, 1.0)[:, None], 0.0)


def camera_to_overlap_boxes(boxes: np.ndarray) -> np.ndarray:
    """Camera boxes ``(K, 7)`` ``x, y, z, l, h, w, ry`` -> ``(K, 7)`` boxes for :mod:`scenes.geometry.boxes`.

    The result lives in the right-handed frame ``(x_cam, z_cam, -y_cam)`` (right, forward, up) with
    the geometric centre and a counter-clockwise yaw: ``(x, z, -y + h/2, l, w, h, -ry)``. A camera
    box's length axis is ``(cos ry, -sin ry)`` in the ``(x, z)`` plane (KITTI's and the devkit's
    convention), which is the counter-clockwise direction ``-ry`` there; its vertical extent
    ``[y - h, y]`` (y down) becomes ``[-y, -y + h]`` (up). Overlaps of the results are therefore the
    devkit's BEV and 3D overlaps.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    x, y, z, length, h, w, ry = b.T
    return np.stack([x, z, -y + h / 2.0, length, w, h, -ry], axis=1)


def camera_bev_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact BEV IoU ``(K1, K2)`` of camera boxes ``(K, 7)`` ``x, y, z, l, h, w, ry``."""
    return bev_iou(camera_to_overlap_boxes(a), camera_to_overlap_boxes(b))


def camera_iou3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact 3D IoU ``(K1, K2)`` of camera boxes ``(K, 7)`` ``x, y, z, l, h, w, ry``."""
    return iou3d(camera_to_overlap_boxes(a), camera_to_overlap_boxes(b))


def frame_overlaps(dt: FrameObjects, gt: FrameObjects, metric: Metric) -> np.ndarray:
    """Overlaps ``(D, G)`` of a frame's detections with its ground truth."""
    if len(dt) == 0 or len(gt) == 0:
        return np.zeros((len(dt), len(gt)))
    if metric is Metric.IMAGE:
        return image_iou(dt.bbox, gt.bbox)
    if metric is Metric.BEV:
        return camera_bev_iou(dt.boxes, gt.boxes)
    return camera_iou3d(dt.boxes, gt.boxes)
