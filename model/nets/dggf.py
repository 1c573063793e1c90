"""Point-cloud-text fusion: Dynamic Gated Graph Fusion (section III-D, eqs. 9-12, Algorithm 1,
fig. 6) and the static Gated Graph Fusion of Talk2Radar (spec section 3.5) for table IX.

Both modules map ``lr (B, C, H, W)`` and the text tokens ``(B, L, D)`` with their padding mask
``(B, L)`` (True = padding) to ``lc (B, C, H, W)``; one module per backbone stage.

DGGF, per stage:

- eqs. 9-10: ``W_G = sigmoid(W f_t^s)`` with ``f_t^s`` the max over the *valid* tokens (padding is
  excluded), one gate per channel;
- eq. 11: ``f = W_G * (lr + CPE(lr))``; CPE is a conditional position encoding, a depthwise 3x3
  conv (Chu et al.'s PEG);
- Algorithm 1 (``DynConv``), see :func:`dynamic_axial_graph` and :func:`masked_max_relative`:

  1. ``mu, sigma`` = mean and standard deviation, over the cells, of the Euclidean (L2 over
     channels) distance between ``f`` and its quadrants flipped across the diagonals, i.e. each
     quadrant swapped with the diagonally opposite one (a cyclic shift by ``(H // 2, W // 2)``).
     Statistics are per sample, so a sample's output does not depend on the rest of its batch.
  2. For ``m = 1, 2, ...`` while ``m K < H``: ``X_rolled = roll_down(f, m K)`` (cyclic, as
     MobileViG's SVGA), an edge exists where ``||f - X_rolled||_2 < mu - sigma`` (strict); the
     same along the columns with ``roll_right`` while ``m K < W``.
  3. ``X_final = max(0, max over edges of (X_rolled - f))``: masked max-relative aggregation; the
     running max starts at 0 as in MobileViG's MRConv4d, so a node without edges gets 0.
  4. ``Conv1x1(concat[f, X_final])`` (2C -> C) + BatchNorm.

- eq. 12: ``lc = W_out(GELU(W_in(DynConv(f)))) + lr``; ``W_in``, ``W_out`` are 1x1 convs (C ->
  ``ffn_ratio * C`` -> C) with BatchNorm as Vision GNN's FFN; the residual adds the *ungated*
  ``lr``.

GGF (Talk2Radar, spec 3.5): static max-relative graph with shifts ``K, 2K, ...`` (K = 2) along rows
and columns and no mask, ``y = GELU(BN(Conv1x1([x, x_j])))``, ``g = sigmoid(Linear(t))``,
``out = y * (1 + g)``. Talk2Radar gates with ALBERT's pooled sentence vector; with MiniLM tokens
we use the masked mean of the tokens (MiniLM's own sentence pooling).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import torch
from torch import Tensor, nn


def masked_max_pool(tokens: Tensor, padding_mask: Tensor) -> Tensor:
    """Eq. 9: ``(B, L, D)`` tokens -> ``(B, D)`` max over the tokens where ``padding_mask`` is False."""
    filled = tokens.masked_fill(padding_mask.unsqueeze(-1), float("-inf"))
    return filled.amax(dim=1)


def masked_mean_pool(tokens: Tensor, padding_mask: Tensor) -> Tensor:
    """``(B, L, D)`` tokens -> ``(B, D)`` mean over the tokens where ``padding_mask`` is False."""
    valid = (~padding_mask).unsqueeze(-1).to(tokens.dtype)
    return (tokens * valid).sum(dim=1) / valid.sum(dim=1).clamp(min=1.0)


def swap_diagonal_quadrants(x: Tensor) -> Tensor:
    """Each quadrant of ``(B, C, H, W)`` moved to the diagonally opposite one (cyclic half shift)."""
    return torch.roll(x, shifts=(x.shape[-2] // 2, x.shape[-1] // 2), dims=(-2, -1))


def _squared_distance(x: Tensor, other: Tensor) -> Tensor:
    """``(B, H, W)`` squared Euclidean distance over channels (cheaper than ``vector_norm``)."""
    return (x - other).square().sum(dim=1)


def graph_statistics(x: Tensor) -> tuple[Tensor, Tensor]:
    """Algorithm 1, lines 1-2: ``mu, sigma`` of ``||x - swap_diagonal_quadrants(x)||_2``.

    Args:
        x: ``(B, C, H, W)``.

    Returns:
        ``mu, sigma``, each ``(B,)``: mean and (unbiased) standard deviation over the ``H * W``
        cells of the channel-wise Euclidean distance.
    """
    dist = _squared_distance(x, swap_diagonal_quadrants(x)).flatten(1).sqrt()
    return dist.mean(dim=1), dist.std(dim=1)


_Pass = tuple[int, int, Tensor, Tensor]


@dataclass(frozen=True)
class AxialGraph:
    """The dynamic axial graph of Algorithm 1 for a batch of maps.

    Attributes:
        mu, sigma: ``(B,)`` distance statistics (:func:`graph_statistics`).
        row_shifts: Shifts ``m K`` (``m = 1, 2, ...``, ``m K < H``) of ``roll_down``.
        row_masks: ``(B, len(row_shifts), H, W)`` bool: cell ``(i, j)`` is linked to cell
            ``((i - s) mod H, j)`` for shift ``s``.
        col_shifts: Shifts of ``roll_right`` (``m K < W``).
        col_masks: ``(B, len(col_shifts), H, W)`` bool: link to ``(i, (j - s) mod W)``.
    """

    mu: Tensor
    sigma: Tensor
    row_shifts: tuple[int, ...]
    row_masks: Tensor
    col_shifts: tuple[int, ...]
    col_masks: Tensor


def _axial_passes(x: Tensor, k: int) -> tuple[Tensor, Tensor, Iterator[_Pass]]:
    """Shared loop of Algorithm 1: ``mu, sigma`` and a lazy sequence of rolls, each
    ``(dim, shift, mask (B, H, W), X_rolled - x)``.

    The edge test ``||x - X_rolled||_2 < mu - sigma`` is evaluated on squared distances (no edge
    at all when ``mu - sigma <= 0``): the same test without a square root per cell. The statistics
    only decide the edges, so no gradient flows through them.
    """
    if k < 1:
        raise ValueError(f"graph step K must be >= 1, got {k}")
    b, _, height, width = x.shape
    mu, sigma, limit = _edge_limit(x)
    limit = limit.view(b, 1, 1)

    def passes() -> Iterator[_Pass]:
        for dim, size in ((-2, height), (-1, width)):
            for shift in range(k, size, k):
                diff = torch.roll(x, shift, dims=dim) - x
                with torch.no_grad():
                    mask = diff.detach().square().sum(dim=1) < limit
                yield dim, shift, mask, diff

    return mu, sigma, passes()


def _edge_limit(x: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """``mu, sigma`` and the squared edge threshold ``(mu - sigma)^2``, each ``(B,)``.

    The limit is 0 where ``mu - sigma <= 0``, so the strict test ``distance^2 < limit`` then links
    nothing. Computed without gradients: the statistics only decide the edges.
    """
    with torch.no_grad():
        mu, sigma = graph_statistics(x.detach())
        threshold = mu - sigma
        limit = torch.where(threshold > 0, threshold.square(), torch.zeros_like(threshold))
    return mu, sigma, limit


def dynamic_axial_graph(x: Tensor, k: int) -> AxialGraph:
    """Algorithm 1's edges (lines 1-7 and 12-16) for ``x (B, C, H, W)`` and step ``K``; pure."""
    b, _, height, width = x.shape
    mu, sigma, lazy = _axial_passes(x, k)
    passes = list(lazy)
    empty = torch.zeros(b, 0, height, width, dtype=torch.bool, device=x.device)

    def stack(dim: int) -> tuple[tuple[int, ...], Tensor]:
        chosen = [(s, m) for d, s, m, _ in passes if d == dim]
        if not chosen:
            return (), empty
        return tuple(s for s, _ in chosen), torch.stack([m for _, m in chosen], dim=1)

    row_shifts, row_masks = stack(-2)
    col_shifts, col_masks = stack(-1)
    return AxialGraph(mu, sigma, row_shifts, row_masks, col_shifts, col_masks)


def dynamic_max_relative(x: Tensor, k: int) -> Tensor:
    """Algorithm 1, lines 1-19: ``X_final = max(0, max over edges of (X_rolled - x))``.

    Both forms give the same values. With gradients recorded (training) the grouped form
    (:func:`_grouped_axis_max`) runs when ``K`` divides both axes and the pairwise tensor stays
    small: one wide max whose backward is a single scatter instead of a chain of ``maximum``
    backwards (3.5-6x faster per training step here). Without gradients (inference) the roll loop
    is faster and lighter, so it runs instead.
    """
    _, c, height, width = x.shape
    pairs = x.shape[0] * c * height * width * max(height, width) // max(k, 1)
    grouped_ok = k >= 1 and height % k == 0 and width % k == 0 and pairs <= _GROUPED_MAX_ELEMENTS
    if grouped_ok and torch.is_grad_enabled() and x.requires_grad:
        _, _, limit = _edge_limit(x)
        rows = _grouped_axis_max(x, k, limit)
        cols = _grouped_axis_max(x.transpose(-1, -2), k, limit).transpose(-1, -2)
        return torch.maximum(rows, cols)
    return dynamic_max_relative_loop(x, k)


_GROUPED_MAX_ELEMENTS = 64 * 1024 * 1024
"""Largest pairwise tensor (elements) the grouped form builds; beyond it the roll loop runs."""


def _grouped_axis_max(x: Tensor, k: int, limit: Tensor) -> Tensor:
    """Masked max-relative over the row rolls ``m K`` (``m = 1 .. H/K - 1``) in one pass.

    With ``H = n K``, ``roll_down(x, m K)`` brings row ``i = a K + r`` the row ``(a - m) K + r``
    (mod ``H``): over all ``m`` these are exactly the other rows of the same residue ``r``. So the
    result is, per row, the masked maximum of ``x[a'] - x[a]`` over the ``n`` rows ``a'`` of its
    residue class; the term ``a' = a`` is 0, which the running maximum's start value 0 already is.

    Args:
        x: ``(B, C, H, W)`` with ``H % k == 0``.
        limit: ``(B,)`` squared distance threshold ``(mu - sigma)^2`` (0: no edges).

    Returns:
        ``(B, C, H, W)``.
    """
    b, c, height, width = x.shape
    n = height // k
    grouped = x.reshape(b, c, n, k, width)
    diff = grouped.unsqueeze(2) - grouped.unsqueeze(3)  # (B, C, n[a], n[a'], K, W): x[a'] - x[a]
    with torch.no_grad():
        mask = diff.detach().square().sum(dim=1) < limit.view(b, 1, 1, 1, 1)
    return (diff * mask.unsqueeze(1).to(x.dtype)).amax(dim=3).reshape(b, c, height, width)


def dynamic_max_relative_loop(x: Tensor, k: int) -> Tensor:
    """Algorithm 1 as written: one roll, mask and running maximum per shift (the reference)."""
    out = torch.zeros_like(x)
    _, _, passes = _axial_passes(x, k)
    for _, _, mask, diff in passes:
        out = torch.maximum(out, diff * mask.unsqueeze(1).to(x.dtype))
    return out


def masked_max_relative(x: Tensor, graph: AxialGraph) -> Tensor:
    """Max-relative aggregation over a precomputed :class:`AxialGraph` (same result as
    :func:`dynamic_max_relative` when ``graph = dynamic_axial_graph(x, k)``)."""
    out = torch.zeros_like(x)
    for i, s in enumerate(graph.row_shifts):
        mask = graph.row_masks[:, i : i + 1].to(x.dtype)
        out = torch.maximum(out, (torch.roll(x, s, dims=-2) - x) * mask)
    for i, s in enumerate(graph.col_shifts):
        mask = graph.col_masks[:, i : i + 1].to(x.dtype)
        out = torch.maximum(out, (torch.roll(x, s, dims=-1) - x) * mask)
    return out


def static_max_relative(x: Tensor, k: int) -> Tensor:
    """GGF's MRConv4d aggregation: ``max(0, max_s (x - roll(x, s)))`` for ``s = k, 2k, ...`` along
    rows then columns (spec 3.5; note the sign ``x - rolled`` of Talk2Radar's code)."""
    out = torch.zeros_like(x)
    for s in range(k, x.shape[-2], k):
        out = torch.maximum(out, x - torch.roll(x, s, dims=-2))
    for s in range(k, x.shape[-1], k):
        out = torch.maximum(out, x - torch.roll(x, s, dims=-1))
    return out


class DynamicGatedGraphFusion(nn.Module):
    """DGGF of one stage (eqs. 9-12, Algorithm 1).

    Args:
        channels: ``C`` of the stage.
        text_dim: ``D`` of the text tokens.
        k: Roll step ``K`` of the axial graph.
        ffn_ratio: Hidden width of the feed-forward as a multiple of ``C``.
    """

    def __init__(self, channels: int, text_dim: int, k: int, ffn_ratio: int = 2) -> None:
        super().__init__()
        self.k = k
        self.gate = nn.Linear(text_dim, channels)  # W of eq. 10
        self.cpe = nn.Conv2d(channels, channels, 3, padding=1, groups=channels)
        self.graph_conv = nn.Sequential(
            nn.Conv2d(2 * channels, channels, 1, bias=False), nn.BatchNorm2d(channels)
        )
        hidden = ffn_ratio * channels
        self.w_in = nn.Sequential(
            nn.Conv2d(channels, hidden, 1, bias=False), nn.BatchNorm2d(hidden)
        )
        self.w_out = nn.Sequential(
            nn.Conv2d(hidden, channels, 1, bias=False), nn.BatchNorm2d(channels)
        )
        self.act = nn.GELU()

    def dyn_conv(self, f: Tensor) -> Tensor:
        """Algorithm 1: ``Conv2d(Concat(f, X_final))``."""
        return self.graph_conv(torch.cat([f, dynamic_max_relative(f, self.k)], dim=1))

    def forward(self, lr: Tensor, tokens: Tensor, padding_mask: Tensor) -> Tensor:
        """``lr (B, C, H, W)``, ``tokens (B, L, D)``, ``padding_mask (B, L)`` -> ``lc (B, C, H, W)``."""
        gate = torch.sigmoid(self.gate(masked_max_pool(tokens, padding_mask)))  # W_G, (B, C)
        f = gate[:, :, None, None] * (lr + self.cpe(lr))  # eq. 11
        return self.w_out(self.act(self.w_in(self.dyn_conv(f)))) + lr  # eq. 12


class GatedGraphFusion(nn.Module):
    """Talk2Radar's static GGF of one stage (spec section 3.5): ``y * (1 + g)``."""

    def __init__(self, channels: int, text_dim: int, k: int = 2) -> None:
        super().__init__()
        self.k = k
        self.graph_conv = nn.Sequential(
            nn.Conv2d(2 * channels, channels, 1), nn.BatchNorm2d(channels), nn.GELU()
        )
        self.gate = nn.Linear(text_dim, channels)

    def forward(self, lr: Tensor, tokens: Tensor, padding_mask: Tensor) -> Tensor:
        """Same call as :class:`DynamicGatedGraphFusion`."""
        y = self.graph_conv(torch.cat([lr, static_max_relative(lr, self.k)], dim=1))
        g = torch.sigmoid(self.gate(masked_mean_pool(tokens, padding_mask)))
        return y * (1.0 + g[:, :, None, None])
