"""BACA's attention at CPU inference (issue 20): reused score buffers, blocks that stay in the
core's cache, and, for one head, the projections folded into the agents.

:mod:`model.nets.fusion.baca` defines the fusion; its training form and every other device run the
plain products. On the CPU without gradients it calls these forms, which compute the same
functions:

- :func:`softmax_scores`: ``softmax(scale * a @ x (+ bias))`` into per-thread buffers reused across
  calls (:func:`scratch`);
- :func:`attend_blocked`: eq. 7 of one item and head, its score matrices a block at a time;
- :func:`folded_direction`: one direction of one-head BACA without its projections of the maps.
  With one head the agents are ``A = W_Q pool(x_a) + b_Q`` (pooling is an average: it commutes
  with the affine map), and every product with a projected map is a product with the map itself:
  the agents' scores ``A^T K_b = (W_K^T A)^T x_b + A^T b_K``, whose second term is a constant per
  agent that the softmax over the cells drops; the context ``V_b G^T = W_V (x_b G^T) + b_V`` (a
  softmax row sums to 1); the queries' scores ``Q_a^T A = x_a^T (W_Q^T A) + 1 (b_Q^T A)``; the
  output ``W_O (C S^T) + b_O = (W_O C) S^T + b_O``, whose bias the merge takes
  (:func:`model.nets.fusion.shared.merged`). The four ``C x C`` projections of the ``L`` cells become
  products with the ``l`` agents, and the attention's four products keep their sizes: equal to
  the plain form up to float rounding.
"""

from __future__ import annotations

import math
import threading

import torch
import torch.nn.functional as F
from torch import Tensor, nn

_SCRATCH = threading.local()
"""Per-thread score buffers of CPU inference (:func:`softmax_scores`)."""

BLOCK_SCORES = 1 << 18
"""Scores per block (1 MB of float32) of the blocked attentions: about half of a core's L2."""


def scratch(slot: str, shape: tuple[int, ...], like: Tensor) -> Tensor:
    """A buffer of ``shape`` for CPU inference, kept per thread and reused across calls (grown
    when a call needs more). Without it every call allocates its multi-megabyte score tensors
    afresh, and the allocator hands them back to the system and faults them in again on each
    call (thousands of page faults per scene at the first stage)."""
    buffers = getattr(_SCRATCH, "buffers", None)
    if buffers is None:
        buffers = _SCRATCH.buffers = {}
    numel = math.prod(shape)
    buf = buffers.get((slot, like.dtype))
    if buf is None or buf.numel() < numel:
        buf = buffers[(slot, like.dtype)] = torch.empty(numel, dtype=like.dtype)
    return buf[:numel].view(shape)


def softmax_scores(a: Tensor, x: Tensor, scale: float, bias: Tensor | None = None) -> Tensor:
    """``softmax(scale * a @ x + bias)`` over the last dim: ``(N, M, d) @ (N, d, K) -> (N, M,
    K)``, the scale applied inside the product, ``bias`` ``(K,)`` added to every row. CPU
    inference writes into :func:`scratch` buffers (the result is only valid until the next call
    on this thread: consume it at once)."""
    shape = (a.shape[0], a.shape[1], x.shape[2])
    if a.device.type != "cpu" or torch.is_grad_enabled():
        out = torch.empty(shape, dtype=a.dtype, device=a.device)
        if bias is None:
            return torch.baddbmm(out, a, x, beta=0.0, alpha=scale).softmax(dim=-1)
        out.copy_(bias.expand(shape))
        return torch.baddbmm(out, a, x, alpha=scale).softmax(dim=-1)
    scores = scratch("scores", shape, a)
    if bias is None:
        torch.baddbmm(scores, a, x, beta=0.0, alpha=scale, out=scores)
    else:
        scores.copy_(bias.expand(shape))
        torch.baddbmm(scores, a, x, alpha=scale, out=scores)
    return torch.softmax(scores, -1, out=scratch("probabilities", shape, a))


def blocked(q: Tensor, agents: Tensor) -> bool:
    """Whether :func:`attend_blocked` serves an attention of queries ``q (1, d, L)`` and agents
    ``(1, d, l)``: CPU inference whose ``(l, L)`` scores do not fit two blocks (BACA's first
    stage, 144 x 6400 on the small preset)."""
    cells, count = q.shape[-1], agents.shape[-1]
    return (
        q.device.type == "cpu" and not torch.is_grad_enabled() and cells * count > 2 * BLOCK_SCORES
    )


def attend_blocked(q: Tensor, k: Tensor, v: Tensor, agents: Tensor, scale: float) -> Tensor:
    """:meth:`model.nets.fusion.baca.AgentCrossAttention.attend` of one item and head, ``q, k, v (d,
    L)``, ``agents (d, l)`` -> ``f_ag (d, L)``, in blocks: the agents' scores a block of agents
    at a time and the queries' a block of queries at a time, each block's product, softmax and
    product done while its scores are still in the core's cache (whole, they are a few
    megabytes, written and read back from memory three times). Each output is the same sum of
    the same products as unblocked (a block is a slice of rows or columns of one product): equal
    to float rounding, and bit for bit where the BLAS keeps its summation order across block
    shapes (measured so on the shipped model's first stage here: 40 agents, 1820 cells a
    block)."""
    d, cells = q.shape
    count = agents.shape[1]
    context = q.new_empty(d, count)  # f_ac^T
    step = max(1, BLOCK_SCORES // cells)
    for i in range(0, count, step):
        gather = softmax_scores(agents[None, :, i : i + step].transpose(1, 2), k[None], scale)
        torch.mm(v, gather[0].t(), out=context[:, i : i + step])
    out = q.new_empty(d, cells)
    step = max(1, BLOCK_SCORES // count)
    for j in range(0, cells, step):
        spread = softmax_scores(q[None, :, j : j + step].transpose(1, 2), agents[None], scale)
        torch.mm(context, spread[0].t(), out=out[:, j : j + step])
    return out


def folded_direction(
    q: nn.Linear,
    k: nn.Linear,
    v: nn.Linear,
    o: nn.Linear,
    agent_size: tuple[int, int],
    xa: Tensor,
    xb: Tensor,
    fa: Tensor,
    out: Tensor,
) -> None:
    """One direction of one-head BACA at CPU inference (module docstring): ``out (C, L) = fa +
    f_ag W_O`` without ``W_O``'s bias, from the position-encoded maps ``xa`` (queries' sensor,
    ``(C, H, W)``) and ``xb`` (keys' and values' sensor, ``(C, L)``), ``fa (C, L)`` the
    queries' sensor's own map; ``q, k, v, o`` the direction's projections. The agents' and the
    queries' scores run in blocks (:data:`BLOCK_SCORES`)."""
    c, height, width = xa.shape
    cells = height * width
    scale = c**-0.5
    pooled = F.adaptive_avg_pool2d(xa[None], agent_size).reshape(c, -1)
    agents = torch.addmm(q.bias[:, None], q.weight, pooled)  # A = pool(Q_a), (C, l)
    count = agents.shape[1]
    to_keys = torch.mm(k.weight.t(), agents)  # W_K^T A: the agents' scores over x_b
    to_queries = torch.mm(q.weight.t(), agents)  # W_Q^T A: the queries' scores from x_a
    query_bias = torch.mv(agents.t(), q.bias) * scale  # b_Q^T A
    context = xa.new_empty(c, count)  # x_b G^T
    step = max(1, BLOCK_SCORES // cells)
    for i in range(0, count, step):
        gather = softmax_scores(to_keys[None, :, i : i + step].transpose(1, 2), xb[None], scale)
        torch.mm(xb, gather[0].t(), out=context[:, i : i + step])
    mixed = torch.mm(o.weight, torch.addmm(v.bias[:, None], v.weight, context))  # W_O V G^T
    queries = xa.reshape(c, cells)
    step = max(1, BLOCK_SCORES // count)
    for j in range(0, cells, step):
        block = queries[None, :, j : j + step].transpose(1, 2)
        spread = softmax_scores(block, to_queries[None], scale, query_bias)
        torch.addmm(fa[:, j : j + step], mixed, spread[0].t(), out=out[:, j : j + step])


__all__ = [
    "BLOCK_SCORES",
    "attend_blocked",
    "blocked",
    "folded_direction",
    "scratch",
    "softmax_scores",
]
