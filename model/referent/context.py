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
  other candidates ``j`` (how many come first, each weighted by its objectness ``w_j``, a soft
  step of its detection score at :data:`OBJECT_SCORE`: :func:`objectness`), given
  as ``min(r, 6) / 4`` and as bumps ``exp(-(r - n)^2 / (2 * 0.35^2))`` at ``n = 0 .. 3``; plus the
  objectness mass of the candidate's class.
- **Relations** (:data:`RELATION_FEATURES`): for each class ``c`` and each *reference* of that
  class (its nearest, farthest, leftmost, rightmost candidate, and the ``c`` candidate closest to
  this one), the reference's soft position (a softmax over ``c``'s candidates of the ordering key
  over ``tau`` plus the log objectness, so that a faint detection must be much more
  extreme to be the reference), and from it: ``dx``, ``dy`` and the BEV distance of the
  reference's centre from this candidate's, this candidate's depth beyond the reference's far edge
  (what "behind" measures), the weight this candidate itself has in the reference (1: it *is* the
  nearest car), and this candidate's soft rank by distance to the reference among its own class,
  as ``min(r, 6) / 4`` and bumps at 0 and 1 ("closest to", "second closest to"; the reference
  itself is no rival), plus the objectness mass of each class.

Frames and units: LiDAR frame (x forward, y left), metres; distances are divided by
:data:`RELATION_SCALE`. ``K = 0`` gives ``(0, CONTEXT_FEATURES)``.
"""

from __future__ import annotations

import numpy as np

from model.referent.candidates import nearest_depth
from scenes.actors import CLASSES

OBJECT_SCORE = 0.3
OBJECT_WIDTH = 0.05
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
RANK_NAMES = ("nearest", "farthest", "leftmost", "rightmost", "nearest_all", "farthest_all")
"""The orderings of the rank block, in order."""


def rank_columns(order: str) -> slice:
    """Columns of ordering ``order`` (:data:`RANK_NAMES`): ``min(r, 6) / 4``, then the bumps."""
    i = RANK_NAMES.index(order)
    return slice(i * (1 + len(BUMPS)), (i + 1) * (1 + len(BUMPS)))


def relation_columns(cls: str, reference: str) -> slice:
    """Columns of the relation to class ``cls``'s ``reference`` (:data:`REFERENCES`): dx, dy,
    distance, depth beyond its far edge, own weight, rank / 4, bump 0, bump 1."""
    start = RANK_FEATURES + CLASSES.index(cls) * (len(REFERENCES) * PER_REFERENCE + 1)
    start += REFERENCES.index(reference) * PER_REFERENCE
    return slice(start, start + PER_REFERENCE)


def _sigmoid(z: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * z))


def objectness(scores: np.ndarray) -> np.ndarray:
    """How much a candidate of detection score ``s`` counts as an object, ``(K,)`` in ``(0, 1)``:
    ``sigmoid((s - OBJECT_SCORE) / OBJECT_WIDTH)``. A detector's faint peaks are many (up to 40
    candidates above the 0.05 candidate threshold, about a third of a scene's score mass below
    0.3); weighted by their raw scores they added up to whole places in a rank."""
    return _sigmoid((np.clip(scores, 0.0, 1.0) - OBJECT_SCORE) / OBJECT_WIDTH)


def _rank_code(rank: np.ndarray, bumps: tuple[int, ...]) -> np.ndarray:
    """``(..., 1 + len(bumps))`` of soft ranks ``(...)``: ``min(r, 6) / 4`` and a Gaussian bump
    at each ``n``."""
    cols = [np.minimum(rank, 6.0) / 4.0]
    cols += [np.exp(-((rank - n) ** 2) / (2 * BUMP_WIDTH**2)) for n in bumps]
    return np.stack(cols, axis=-1)


def _softmax_last(logits: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """Softmax of ``logits`` over the last axis, over the ``allowed`` entries only (a row with
    none: all zeros)."""
    z = np.where(allowed, logits, -np.inf)
    top = z.max(axis=-1, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    e = np.where(allowed, np.exp(z - top), 0.0)
    total = e.sum(axis=-1, keepdims=True)
    return np.divide(e, total, out=np.zeros_like(e), where=total > 0)


def _references(
    x: np.ndarray, y: np.ndarray, depth: np.ndarray, labels: np.ndarray, log_w: np.ndarray
) -> np.ndarray:
    """Reference weights ``(C * R, K, K)``: ``[c * R + r, i, j]`` is candidate ``j``'s share in
    class ``c``'s reference ``r`` (:data:`REFERENCES`) as seen from candidate ``i``."""
    k = len(x)
    n_cls, n_ref = len(CLASSES), len(REFERENCES)
    of_c = labels[None, :] == np.arange(n_cls)[:, None]  # (C, K)
    keys = np.stack([-depth, depth, y, -y])  # nearest, farthest, leftmost, rightmost
    logit = keys[None, :, :] / REFERENCE_TAU + log_w  # (C, 4, K)
    extreme = _softmax_last(logit, of_c[:, None, :])  # (C, 4, K): the same from every i
    dist = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :])
    # The c candidate closest to candidate i, itself excluded.
    allowed = of_c[:, None, :] & ~np.eye(k, dtype=bool)[None]
    closest = _softmax_last((-dist / REFERENCE_TAU + log_w[None, :])[None], allowed)  # (C, K, K)
    out = np.empty((n_cls, n_ref, k, k))
    out[:, :4] = extreme[:, :, None, :]
    out[:, 4] = closest
    return out.reshape(n_cls * n_ref, k, k)


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
    w = objectness(np.asarray(scores, dtype=np.float64).reshape(k))
    depth = nearest_depth(b)
    x, y = b[:, 0], b[:, 1]
    others = ~np.eye(k, dtype=bool)
    same = (labels[:, None] == labels[None, :]) & others

    # Ranks: [order, i, j] = w_j sigmoid((key_j - key_i) / tau) over the order's set.
    keys = np.stack([-depth, depth, y, -y, -depth, depth])
    member = np.stack([same] * 4 + [others] * 2)
    step = _sigmoid((keys[:, None, :] - keys[:, :, None]) / RANK_TAU)
    ranks = (step * w * member).sum(axis=2)  # (6, K)
    n_cls = len(CLASSES)
    mass = np.array([w[labels == c].sum() for c in range(n_cls)])
    rank_part = np.concatenate(
        [_rank_code(r, BUMPS) for r in ranks] + [(mass[labels] / 4.0)[:, None]], axis=1
    )

    # Relations, all C * R references at once ([q, i] rows).
    a = _references(x, y, depth, labels, np.log(np.maximum(w, 1e-6)))
    rx, ry, redge = a @ x, a @ y, a @ (2.0 * x - depth)  # (Q, K)
    dx, dy = rx - x, ry - y
    # Each candidate's soft rank by distance to (its own row's) reference among its class:
    # "the pedestrian closest to the nearest car" is the pedestrian ranked 0; the reference
    # itself is no rival (weights 1 - a).
    to_ref = np.hypot(x[None, None, :] - rx[:, :, None], y[None, None, :] - ry[:, :, None])
    diag = np.diagonal(to_ref, axis1=1, axis2=2)  # (Q, K)
    step = _sigmoid((diag[:, :, None] - to_ref) / RANK_TAU)
    rank = (step * (w * (1.0 - a)) * same).sum(axis=2)
    place = np.stack(
        [
            dx / RELATION_SCALE,
            dy / RELATION_SCALE,
            np.hypot(dx, dy) / RELATION_SCALE,
            (depth - redge) / RELATION_SCALE,
            np.diagonal(a, axis1=1, axis2=2),
        ],
        axis=2,
    )
    block = np.concatenate([place, _rank_code(rank, (0, 1))], axis=2)  # (Q, K, PER_REFERENCE)
    block = np.where((a.sum(axis=2) > 0)[..., None], block, 0.0)
    per_class = block.reshape(n_cls, len(REFERENCES), k, PER_REFERENCE).transpose(0, 2, 1, 3)
    per_class = per_class.reshape(n_cls, k, len(REFERENCES) * PER_REFERENCE)
    masses = np.broadcast_to(mass[:, None, None] / 4.0, (n_cls, k, 1))
    relation_part = np.concatenate([per_class, masses], axis=2).transpose(1, 0, 2).reshape(k, -1)
    out = np.concatenate([rank_part, relation_part], axis=1).astype(np.float32)
    assert out.shape == (k, CONTEXT_FEATURES), out.shape
    return out


__all__ = [
    "CONTEXT_FEATURES",
    "RANK_NAMES",
    "REFERENCES",
    "context_features",
    "objectness",
    "rank_columns",
    "relation_columns",
]
