"""Each candidate's place among the scene's other candidates: ranks and relations, text-free.

The referent stage compares candidates through self-attention, which learns a superlative ("the
nearest car") well but an ordinal ("the second closest cyclist", "third from the left") or a
relation to another object ("the pedestrian closest to the nearest car", "the cyclist behind the
car") poorly from a few thousand scenes: both need a comparison of every candidate with every
other, and, for relations, with one candidate the sentence picks out. This module states those
comparisons explicitly, for every candidate at once, as pure numpy functions of the candidates'
boxes, classes and detection scores (no text; the stage decides which of them the sentence asks
about):

- **Ranks** (:data:`RANK_FEATURES`): for each ordering (nearest and farthest by nearest-edge depth,
  leftmost and rightmost by centre ``y`` among the candidate's own class; nearest and farthest
  among all classes), a *soft rank* ``r_i = sum_j w_j sigmoid((key_j - key_i) / tau)`` over the
  other candidates ``j`` (how many, weighted by their detection scores ``w_j``, come first), given
  as ``min(r, 6) / 4`` and as bumps ``exp(-(r - n)^2 / (2 * 0.35^2))`` at ``n = 0 .. 3``; plus the
  score mass of the candidate's class.
- **Relations** (:data:`RELATION_FEATURES`): for each class ``c`` and each *reference* of that
  class (its nearest, farthest, leftmost, rightmost candidate, and the ``c`` candidate closest to
  this one), the reference's soft position (a softmax over ``c``'s candidates of the ordering key
  over ``tau`` plus twice the log detection score, so that a faint detection must be much more
  extreme to be the reference), and from it: ``dx``, ``dy`` and the BEV distance of the
  reference's centre from this candidate's, this candidate's depth beyond the reference's far edge
  (what "behind" measures), the weight this candidate itself has in the reference (1: it *is* the
  nearest car), and this candidate's soft rank by distance to the reference among its own class,
  as ``min(r, 6) / 4`` and bumps at 0 and 1 ("closest to", "second closest to"; the reference
  itself is no rival), plus the score mass of each class.

Frames and units: LiDAR frame (x forward, y left), metres; distances are divided by
:data:`RELATION_SCALE`. ``K = 0`` gives ``(0, CONTEXT_FEATURES)``.
"""

from __future__ import annotations

import numpy as np

from model.referent.candidates import nearest_depth
from scenes.actors import CLASSES

RANK_TAU = 0.5
"""Metres over which a soft rank's step goes from 0.27 to 0.73."""
REFERENCE_TAU = 0.5
"""Metres per unit of a reference softmax's logit."""
RELATION_SCALE = 10.0
BUMPS = (0, 1, 2, 3)
BUMP_WIDTH = 0.35
RANK_ORDERS = 6
"""Same class: nearest, farthest, leftmost, rightmost; all classes: nearest, farthest."""
RANK_FEATURES = RANK_ORDERS * (1 + len(BUMPS)) + 1
REFERENCES = ("nearest", "farthest", "leftmost", "rightmost", "closest")
PER_REFERENCE = 8
"""dx, dy, distance, depth beyond the far edge, own weight, rank / 4, bump 0, bump 1."""
RELATION_FEATURES = len(CLASSES) * (len(REFERENCES) * PER_REFERENCE + 1)
CONTEXT_FEATURES = RANK_FEATURES + RELATION_FEATURES


def _sigmoid(z: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * z))


def soft_rank(key: np.ndarray, weight: np.ndarray, member: np.ndarray) -> np.ndarray:
    """``(K,)`` soft ranks: for each ``i``, ``sum_j w_j sigmoid((key_j - key_i) / RANK_TAU)`` over
    ``j != i`` with ``member[i, j]`` (``key``: larger comes first; ``member``: ``(K, K)`` bool)."""
    k = len(key)
    step = _sigmoid((key[None, :] - key[:, None]) / RANK_TAU)
    mask = member & ~np.eye(k, dtype=bool)
    return (step * weight[None, :] * mask).sum(axis=1)


def _rank_code(rank: np.ndarray, bumps: tuple[int, ...]) -> np.ndarray:
    """``(K, 1 + len(bumps))``: ``min(r, 6) / 4`` and a Gaussian bump at each ``n``."""
    cols = [np.minimum(rank, 6.0) / 4.0]
    cols += [np.exp(-((rank - n) ** 2) / (2 * BUMP_WIDTH**2)) for n in bumps]
    return np.stack(cols, axis=1)


def _softmax_rows(logits: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """Row-wise softmax of ``logits`` ``(R, K)`` over the ``allowed`` entries (rows with none:
    all zeros)."""
    z = np.where(allowed, logits, -np.inf)
    top = z.max(axis=1, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    e = np.where(allowed, np.exp(z - top), 0.0)
    total = e.sum(axis=1, keepdims=True)
    return np.divide(e, total, out=np.zeros_like(e), where=total > 0)


def context_features(boxes: np.ndarray, labels: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """Ranks and relations of ``K`` candidates (module docstring).

    Args:
        boxes: ``(K, 7)`` LiDAR frame.
        labels: ``(K,)`` class indices into :data:`scenes.actors.CLASSES`.
        scores: ``(K,)`` detection scores in ``[0, 1]``.

    Returns:
        ``(K, CONTEXT_FEATURES)`` float32.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    k = len(b)
    if k == 0:
        return np.zeros((0, CONTEXT_FEATURES), dtype=np.float32)
    labels = np.asarray(labels, dtype=np.int64).reshape(k)
    w = np.clip(np.asarray(scores, dtype=np.float64).reshape(k), 0.0, 1.0)
    depth = nearest_depth(b)
    x, y = b[:, 0], b[:, 1]
    same = labels[:, None] == labels[None, :]
    every = np.ones((k, k), dtype=bool)

    orders = (
        (-depth, same), (depth, same), (y, same), (-y, same), (-depth, every), (depth, every),
    )  # fmt: skip
    parts = [_rank_code(soft_rank(key, w, member), BUMPS) for key, member in orders]
    mass = np.array([w[labels == c].sum() for c in range(len(CLASSES))])
    parts.append((mass[labels] / 4.0)[:, None])

    log_w = 2.0 * np.log(np.maximum(w, 1e-6))
    dist = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :])
    far_edge = 2.0 * x - depth
    keys = {"nearest": -depth, "farthest": depth, "leftmost": y, "rightmost": -y}
    for c in range(len(CLASSES)):
        of_c = labels == c
        for name in REFERENCES:
            if name == "closest":
                # Row i: the c candidate closest to candidate i, itself excluded.
                allowed = of_c[None, :] & ~np.eye(k, dtype=bool)
                a = _softmax_rows(-dist / REFERENCE_TAU + log_w[None, :], allowed)
            else:
                logit = keys[name] / REFERENCE_TAU + log_w
                a = np.repeat(_softmax_rows(logit[None, :], of_c[None, :]), k, axis=0)
            present = a.sum(axis=1) > 0
            rx, ry, redge = a @ x, a @ y, a @ far_edge
            dx, dy = rx - x, ry - y
            d = np.hypot(dx, dy)
            # Each candidate's soft rank by distance to (its own row's) reference among its class:
            # "the pedestrian closest to the nearest car" is the pedestrian ranked 0.
            to_ref = np.hypot(x[None, :] - rx[:, None], y[None, :] - ry[:, None])  # [i, j]
            diag = to_ref[np.arange(k), np.arange(k)]
            step = _sigmoid((diag[:, None] - to_ref) / RANK_TAU)
            # The reference itself is no rival (weights 1 - a).
            rivals = w[None, :] * (1.0 - a) * (same & ~np.eye(k, dtype=bool))
            rank = (step * rivals).sum(axis=1)
            block = np.concatenate(
                [
                    np.stack(
                        [
                            dx / RELATION_SCALE,
                            dy / RELATION_SCALE,
                            d / RELATION_SCALE,
                            (depth - redge) / RELATION_SCALE,
                            np.diagonal(a),
                        ],
                        axis=1,
                    ),
                    _rank_code(rank, (0, 1)),
                ],
                axis=1,
            )
            parts.append(np.where(present[:, None], block, 0.0))
        parts.append(np.full((k, 1), mass[c] / 4.0))
    out = np.concatenate(parts, axis=1).astype(np.float32)
    assert out.shape == (k, CONTEXT_FEATURES), out.shape
    return out


__all__ = ["CONTEXT_FEATURES", "context_features", "soft_rank"]
