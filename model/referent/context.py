"""Each candidate's place among the scene's other candidates: ranks and relations, text-free.

The referent stage compares candidates through self-attention, which learns a superlative ("the
nearest car") well but an ordinal ("the second closest cyclist", "third from the left") or a
relation to another object ("the pedestrian closest to the nearest car", "the cyclist behind the
car") poorly from a few thousand scenes: both need a comparison of every candidate with every
other, and, for relations, with one candidate the sentence picks out. This module states those
comparisons explicitly, for every candidate at once, as a pure function of the candidates'
boxes, classes and detection scores (one compiled pass, numba) (no text; the stage decides which of them the sentence asks
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
:data:`RELATION_SCALE`. ``K = 0`` gives ``(0, context_width(C))``; ``C`` classes give ``C``
relation blocks (:data:`CONTEXT_FEATURES` for the three of ``vod``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from model.referent.candidates import nearest_depth
from scenes.geometry.classes import VOD, ClassSet

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
PER_CLASS = len(REFERENCES) * PER_REFERENCE + 1
"""Relation columns per class: its references, then its objectness mass."""
RELATION_FEATURES = len(VOD) * PER_CLASS
"""Relation columns of a three-class (``vod``) model; ``C * PER_CLASS`` for ``C`` classes."""
CONTEXT_FEATURES = RANK_FEATURES + RELATION_FEATURES
"""Width of :func:`context_features` of a three-class (``vod``) model; :func:`context_width`."""


def context_width(num_classes: int) -> int:
    """Width of :func:`context_features` of a model of ``num_classes`` classes."""
    return RANK_FEATURES + num_classes * PER_CLASS


RANK_NAMES = ("nearest", "farthest", "leftmost", "rightmost", "nearest_all", "farthest_all")
"""The orderings of the rank block, in order."""


def rank_columns(order: str) -> slice:
    """Columns of ordering ``order`` (:data:`RANK_NAMES`): ``min(r, 6) / 4``, then the bumps."""
    i = RANK_NAMES.index(order)
    return slice(i * (1 + len(BUMPS)), (i + 1) * (1 + len(BUMPS)))


def relation_columns(cls: str, reference: str, classes: ClassSet = VOD) -> slice:
    """Columns of the relation to class ``cls``'s ``reference`` (:data:`REFERENCES`) for a model
    of ``classes``: dx, dy, distance, depth beyond its far edge, own weight, rank / 4, bump 0,
    bump 1."""
    start = RANK_FEATURES + classes.index(cls) * PER_CLASS
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


@njit(inline="always")
def _step(z: float) -> float:  # pragma: no cover - compiled into the kernel
    """The logistic step, as ``0.5 (1 + tanh(z / 2))`` (its form since the features were
    defined)."""
    return 0.5 * (1.0 + math.tanh(0.5 * z))


@njit(inline="always")
def rank_code_into(out, i, col, rank, bumps):  # pragma: no cover - compiled into the kernel
    """``min(r, 6) / 4`` and a Gaussian bump at each of ``bumps`` into ``out[i, col:]``."""
    out[i, col] = min(rank, 6.0) / 4.0
    for b in range(len(bumps)):
        out[i, col + 1 + b] = math.exp(-((rank - bumps[b]) ** 2) / (2 * BUMP_WIDTH**2))


@njit(inline="always")
def softmax_into(a, logits, allowed, k):  # pragma: no cover - compiled into the kernel
    """``a[:k]`` = softmax of ``logits[:k]`` over the ``allowed`` entries (all zeros if none)."""
    top = -np.inf
    for j in range(k):
        if allowed[j]:
            top = max(top, logits[j])
    total = 0.0
    for j in range(k):
        a[j] = math.exp(logits[j] - top) if allowed[j] else 0.0
        total += a[j]
    for j in range(k):
        a[j] = a[j] / total if total > 0 else 0.0


@njit(nogil=True, cache=True)
def _context(x, y, depth, labels, w, n_cls, out):  # pragma: no cover - compiled
    """The module docstring's features of ``K`` candidates into ``out (K, CONTEXT_FEATURES)``
    (float64 arithmetic, term for term)."""
    k = x.shape[0]
    n_ref = len(REFERENCES)
    log_w = np.empty(k)
    mass = np.zeros(n_cls)
    for j in range(k):
        log_w[j] = math.log(max(w[j], 1e-6))
        mass[labels[j]] += w[j]
    # Ranks: [order, i] = sum_j w_j sigmoid((key_j - key_i) / tau) over the order's set.
    keys = np.empty((6, k))
    for j in range(k):
        keys[0, j], keys[1, j], keys[2, j] = -depth[j], depth[j], y[j]
        keys[3, j], keys[4, j], keys[5, j] = -y[j], -depth[j], depth[j]
    col = 0
    for o in range(6):
        for i in range(k):
            rank = 0.0
            for j in range(k):
                if j != i and (o >= 4 or labels[j] == labels[i]):
                    rank += _step((keys[o, j] - keys[o, i]) / RANK_TAU) * w[j]
            rank_code_into(out, i, col, rank, BUMPS)
        col += 1 + len(BUMPS)
    for i in range(k):
        out[i, col] = mass[labels[i]] / 4.0
    col += 1
    # Relations: class c's reference r as seen from candidate i, a[j] = j's share in it.
    dist = np.empty((k, k))
    for i in range(k):
        for j in range(k):
            dist[i, j] = math.hypot(x[i] - x[j], y[i] - y[j])
    a = np.empty(k)
    logits = np.empty(k)
    allowed = np.empty(k, np.bool_)
    to_ref = np.empty(k)
    for c in range(n_cls):
        start = col + c * (n_ref * PER_REFERENCE + 1)
        for i in range(k):
            out[i, start + n_ref * PER_REFERENCE] = mass[c] / 4.0
        for r in range(n_ref):
            # nearest, farthest, leftmost, rightmost (r < 4): the same reference from every i;
            # the c candidate closest to i, itself excluded (r = 4): one per i
            for i in range(k if r == n_ref - 1 else 1):
                for j in range(k):
                    if r == n_ref - 1:
                        logits[j] = -dist[i, j] / REFERENCE_TAU + log_w[j]
                        allowed[j] = labels[j] == c and j != i
                    else:
                        key = (-depth[j], depth[j], y[j], -y[j])[r]
                        logits[j] = key / REFERENCE_TAU + log_w[j]
                        allowed[j] = labels[j] == c
                softmax_into(a, logits, allowed, k)
                total = 0.0
                rx = ry = redge = 0.0
                for j in range(k):
                    total += a[j]
                    rx += a[j] * x[j]
                    ry += a[j] * y[j]
                    redge += a[j] * (2.0 * x[j] - depth[j])
                if not total > 0:  # no candidate of class c (but i): the blocks stay zeros
                    continue
                for j in range(k):
                    to_ref[j] = math.hypot(x[j] - rx, y[j] - ry)
                for q in range(i, i + 1) if r == n_ref - 1 else range(k):
                    _relation(out, q, start + r * PER_REFERENCE, x, y, depth, labels, w, a, rx,
                              ry, redge, to_ref)  # fmt: skip


@njit(inline="always")
def _relation(out, i, base, x, y, depth, labels, w, a, rx, ry, redge, to_ref):  # pragma: no cover
    """Candidate ``i``'s block of one reference (soft position ``a``, centre ``rx, ry``, far
    edge ``redge``; ``to_ref`` every candidate's distance to it) into ``out[i, base:]``."""
    # i's soft rank by distance to the reference among its own class; the reference itself is
    # no rival (weights 1 - a)
    rank = 0.0
    for j in range(x.shape[0]):
        if j != i and labels[j] == labels[i]:
            rank += _step((to_ref[i] - to_ref[j]) / RANK_TAU) * (w[j] * (1.0 - a[j]))
    dx, dy = rx - x[i], ry - y[i]
    out[i, base + 0] = dx / RELATION_SCALE
    out[i, base + 1] = dy / RELATION_SCALE
    out[i, base + 2] = math.hypot(dx, dy) / RELATION_SCALE
    out[i, base + 3] = (depth[i] - redge) / RELATION_SCALE
    out[i, base + 4] = a[i]
    rank_code_into(out, i, base + 5, rank, (0, 1))


def context_features(
    boxes: np.ndarray, labels: np.ndarray, scores: np.ndarray, num_classes: int = 3
) -> np.ndarray:
    """Ranks and relations of ``K`` candidates (module docstring), in one compiled pass (numba,
    cached beside this file; float64 arithmetic).

    Args:
        boxes: ``(K, 7)`` LiDAR frame.
        labels: ``(K,)`` class indices into the model's class set.
        scores: ``(K,)`` detection scores in ``[0, 1]``.
        num_classes: ``C``, the size of the model's class set (3: ``vod``).

    Returns:
        ``(K, context_width(C))`` float32.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    k = len(b)
    out = np.zeros((k, context_width(num_classes)), dtype=np.float64)
    if k == 0:
        return out.astype(np.float32)
    labels = np.ascontiguousarray(np.asarray(labels, dtype=np.int64).reshape(k))
    w = objectness(np.asarray(scores, dtype=np.float64).reshape(k))
    depth = nearest_depth(b)
    _context(
        np.ascontiguousarray(b[:, 0]), np.ascontiguousarray(b[:, 1]), depth, labels, w,
        num_classes, out,
    )  # fmt: skip
    return out.astype(np.float32)


__all__ = [
    "CONTEXT_FEATURES",
    "PER_CLASS",
    "RANK_NAMES",
    "REFERENCES",
    "context_features",
    "context_width",
    "objectness",
    "rank_code_into",
    "rank_columns",
    "relation_columns",
    "softmax_into",
]
