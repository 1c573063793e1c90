"""LiDAR-radar fusion: Bidirectional Agent Cross Attention (section III-C, eqs. 1-8, fig. 5) and
the alternatives of the paper's fusion ablations (tables V, VI, VIII).

Every module here has the same call: ``fusion(f_l, f_r) -> lr`` with ``f_l, f_r, lr`` of shape
``(B, C, H, W)`` (one backbone stage; one module per stage).

BACA, per stage (``L = H * W`` cells, ``l = h * w`` agents, ``n`` heads of width ``d = C / n``):

- eqs. 1-6: ``Q_L, K_L, V_L = (f_l + PE) W_QL, W_KL, W_VL`` and likewise for radar; ``PE`` is the
  fixed 2D sinusoidal encoding of Vaswani et al. [28] (half the channels encode the row, half the
  column; positions normalised to ``[0, 2 pi]`` so that all stages share one scale); the ``W`` are
  linear maps over channels.
- eq. 7: agents ``A_L = Flat(AdaPool(Q_L))`` (adaptive *average* pooling to ``h x w``, default
  12 x 12), ``f_lc = softmax(A_L K_R^T / sqrt(d)) V_R`` (``l x C``: the LiDAR agents gather the
  radar context), ``f_lg = softmax(Q_L A_L^T / sqrt(d)) f_lc`` (``L x C``: broadcast back to every
  LiDAR query).
- eq. 8: the same with the roles swapped gives the radar-driven motion feature ``f_rm``.
- Cost: the two softmax attentions cost ``O(L l C)`` each, the projections ``O(L C^2)``: linear in
  the number of cells. Vanilla cross attention costs ``O(L^2 C)``.

How ``f_lg`` and ``f_rm`` become ``lr`` (the paper does not say; our choice): each passes through
an output projection ``W_O`` (standard for attention) and is added to its own sensor's features as
a residual; the two enriched maps are concatenated and mixed by a 1x1 conv + BatchNorm + ReLU back
to ``C`` channels::

    lr = ReLU(BN(Conv1x1([f_l + f_lg W_OL, f_r + f_rm W_OR])))

The residuals keep each sensor's own evidence when the other sensor is empty or noisy; the 1x1
mixing lets the network weight the two per channel.

Alternatives (``FusionConfig.kind``), same signature and the same merge so that only the attention
differs:

- ``bi_mhca``: bidirectional vanilla multi-head cross attention, ``softmax(Q_L K_R^T / sqrt(d))
  V_R`` over all ``L`` keys and vice versa (quadratic; on the CPU computed explicitly in query
  chunks to bound memory, on CUDA with PyTorch's fused ``scaled_dot_product_attention``).
- ``lidar_query`` / ``radar_query``: one direction of BACA only (table VIII's ``L_Q + R_KV`` and
  ``R_Q + L_KV``); the other sensor enters the merge unchanged.
- ``conv_gate``: a convolutional gate in the spirit of AGN/LiRaFusion: per-sensor sigmoid gates
  from a 3x3 conv over both maps, ``lr = merge([g_l * f_l, g_r * f_r])``.

Single-modality models do not build a fusion module: ``lr`` is the sensor's own features.
"""

from __future__ import annotations

import math
from functools import lru_cache

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.config import FusionConfig
from model.nets.baca_cpu import attend_blocked, blocked, folded_direction, softmax_scores
from model.nets.folding import batchnorm_affine


@lru_cache(maxsize=32)
def _sinusoidal_pe_cpu(channels: int, height: int, width: int) -> Tensor:
    quarter = channels // 4
    pe = torch.zeros(channels, height, width)
    if quarter == 0:
        return pe
    freqs = 1.0 / (10000.0 ** (torch.arange(quarter, dtype=torch.float32) / quarter))
    rows = (torch.arange(height, dtype=torch.float32) + 0.5) / height * 2 * math.pi
    cols = (torch.arange(width, dtype=torch.float32) + 0.5) / width * 2 * math.pi
    ang_r = rows[None, :] * freqs[:, None]  # (quarter, H)
    ang_c = cols[None, :] * freqs[:, None]  # (quarter, W)
    pe[0:quarter] = torch.sin(ang_r)[:, :, None].expand(-1, -1, width)
    pe[quarter : 2 * quarter] = torch.cos(ang_r)[:, :, None].expand(-1, -1, width)
    pe[2 * quarter : 3 * quarter] = torch.sin(ang_c)[:, None, :].expand(-1, height, -1)
    pe[3 * quarter : 4 * quarter] = torch.cos(ang_c)[:, None, :].expand(-1, height, -1)
    return pe


def sinusoidal_position_encoding(
    channels: int, height: int, width: int, device: torch.device | str = "cpu"
) -> Tensor:
    """Fixed 2D sinusoidal positional encoding ``(1, C, H, W)``.

    Channels ``[0, C/4)`` and ``[C/4, C/2)`` hold ``sin``/``cos`` of the row position, the next two
    quarters the column position, at frequencies ``10000^(-i / (C/4))``; positions are cell centres
    normalised to ``(0, 2 pi)``. Channels beyond ``4 * (C // 4)`` are zero.
    """
    return _sinusoidal_pe_cpu(channels, height, width).to(device).unsqueeze(0)


def _to_heads(x: Tensor, heads: int) -> Tensor:
    """``(B, N, C)`` -> ``(B, heads, N, C / heads)``."""
    b, n, c = x.shape
    return x.view(b, n, heads, c // heads).transpose(1, 2)


def _from_heads(x: Tensor) -> Tensor:
    """``(B, heads, N, d)`` -> ``(B, N, heads * d)``."""
    b, h, n, d = x.shape
    return x.transpose(1, 2).reshape(b, n, h * d)


def _tokens(x: Tensor) -> Tensor:
    """``(B, C, H, W)`` -> ``(B, H * W, C)``."""
    return x.flatten(2).transpose(1, 2)


def _map(x: Tensor, height: int, width: int) -> Tensor:
    """``(B, H * W, C)`` -> ``(B, C, H, W)``."""
    return x.transpose(1, 2).reshape(x.shape[0], x.shape[2], height, width)


def attention(q: Tensor, k: Tensor, v: Tensor) -> Tensor:
    """Softmax attention ``softmax(q k^T / sqrt(d)) v`` on ``(B, heads, N, d)`` tensors."""
    scores = torch.matmul(q, k.transpose(-1, -2)) * (q.shape[-1] ** -0.5)
    return torch.matmul(scores.softmax(dim=-1), v)


def _check_pair(f_l: Tensor, f_r: Tensor, channels: int) -> None:
    """Raise ValueError unless the LiDAR and radar maps are both ``(B, channels, H, W)``."""
    if f_l.shape != f_r.shape or f_l.shape[1] != channels:
        raise ValueError(
            f"fusion expects two (B, {channels}, H, W) maps, got {tuple(f_l.shape)} "
            f"and {tuple(f_r.shape)}"
        )


class _Projections(nn.Module):
    """The query, key, value and output projections of one cross attention over ``heads``."""

    def __init__(self, channels: int, heads: int) -> None:
        super().__init__()
        if channels % heads:
            raise ValueError(f"{heads} heads do not divide {channels} channels")
        self.heads = heads
        self.q = nn.Linear(channels, channels)
        self.k = nn.Linear(channels, channels)
        self.v = nn.Linear(channels, channels)
        self.out = nn.Linear(channels, channels)


def _project_many(linears: tuple[nn.Linear, ...], x: Tensor) -> Tensor:
    """Several ``nn.Linear`` of one input in one product: channel-major ``(B, C_in, L)`` ->
    ``(B, sum C_out, L)``, the outputs stacked along the channels in the order given."""
    weight = torch.cat([lin.weight for lin in linears])
    bias = torch.cat([lin.bias for lin in linears])
    if x.shape[0] == 1:  # one matrix product with the bias as its added term
        return torch.addmm(bias[:, None], weight, x[0]).unsqueeze(0)
    return torch.matmul(weight, x) + bias[:, None]


def _project(linear: nn.Linear, x: Tensor) -> Tensor:
    """``linear`` over the channels of a channel-major ``(B, C_in, L)`` tensor: ``(B, C_out, L)``."""
    return _project_many((linear,), x)


class AgentCrossAttention(_Projections):
    """One direction of BACA (eq. 7, or eq. 8 with the sensors swapped).

    Queries come from sensor ``a``, keys and values from sensor ``b``; returns ``f_ag W_O`` as a
    ``(B, C, H, W)`` map (``f_lg`` for a = LiDAR, ``f_rm`` for a = radar).
    """

    def __init__(self, channels: int, agent_size: tuple[int, int], heads: int) -> None:
        super().__init__(channels, heads)
        self.agent_size = (int(agent_size[0]), int(agent_size[1]))

    def forward(self, xa: Tensor, xb: Tensor) -> Tensor:
        """``xa, xb``: ``(B, C, H, W)`` position-encoded maps of the query and key/value sensors."""
        b, c, height, width = xa.shape
        xa, xb = xa.reshape(b, c, -1), xb.reshape(b, c, -1)
        q = _project(self.q, xa).view(b, c, height, width)
        fused = self.attend(q, _project(self.k, xb), _project(self.v, xb))
        return _project(self.out, fused).view(b, c, height, width)

    def attend(self, q: Tensor, k: Tensor, v: Tensor) -> Tensor:
        """Eq. 7 on projected maps, channel-major as the maps are: ``Q_a`` ``(B, C, H, W)``,
        ``K_b, V_b`` ``(B, C, L)`` (``L = H * W``) -> ``f_ag`` ``(B, C, L)`` (before ``W_O``).

        No transposing copies: every product reads its operands in place; the ``1 / sqrt(d)``
        scale is applied inside the score products; the agents' scores are ``(B n, l, L)``, the
        queries' ``(B n, L, l)`` (each softmax over its last dim). The same values as
        :func:`attention` on token-major tensors, up to float rounding.
        """
        b, c = q.shape[:2]
        n = self.heads
        d = c // n
        scale = d**-0.5
        agents = F.adaptive_avg_pool2d(q, self.agent_size).reshape(b * n, d, -1)  # A_a
        q, k, v = (t.reshape(b * n, d, -1) for t in (q, k, v))
        if b * n == 1 and blocked(q, agents):
            return attend_blocked(q[0], k[0], v[0], agents[0], scale).view(b, c, -1)
        agents_t = agents.transpose(1, 2)  # (B n, l, d)
        gather = softmax_scores(agents_t, k, scale)  # (B n, l, L)
        context = torch.bmm(v, gather.transpose(1, 2))  # f_ac^T: (B n, d, l)
        spread = softmax_scores(q.transpose(1, 2), agents, scale)  # (B n, L, l)
        return torch.bmm(context, spread.transpose(1, 2)).view(b, c, -1)  # f_ag^T


class VanillaCrossAttention(_Projections):
    """One direction of multi-head cross attention over all ``L`` keys (quadratic in cells)."""

    def __init__(self, channels: int, heads: int, chunk: int) -> None:
        super().__init__(channels, heads)
        self.chunk = chunk

    def forward(self, xa: Tensor, xb: Tensor) -> Tensor:
        height, width = xa.shape[-2:]
        q = _to_heads(self.q(_tokens(xa)), self.heads)
        k = _to_heads(self.k(_tokens(xb)), self.heads)
        v = _to_heads(self.v(_tokens(xb)), self.heads)
        if q.device.type == "cuda":
            # Fused kernel: never materialises the (L, L) scores (the paper preset's stage 1 has
            # L = 25,600 cells). Same result as the explicit path below.
            fused = F.scaled_dot_product_attention(q, k, v)
        else:
            # Explicit, chunked over the queries: bounded memory, and FLOP counters see it.
            parts = [
                attention(q[:, :, i : i + self.chunk], k, v)
                for i in range(0, q.shape[2], self.chunk)
            ]
            fused = torch.cat(parts, dim=2)
        return _map(self.out(_from_heads(fused)), height, width)


def _merge(channels: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(2 * channels, channels, 1, bias=False),
        nn.BatchNorm2d(channels, eps=1e-3),
        nn.ReLU(inplace=True),
    )


def _merged(merge: nn.Sequential, both: Tensor, bias: Tensor | None = None) -> Tensor:
    """``merge`` (1x1 conv, BatchNorm, ReLU) of a channel-major ``(B, 2 C, L)`` tensor ->
    ``(B, C, L)``; ``bias`` ``(2 C,)``, when given, is added to every cell of ``both`` first. In
    eval mode for one item: one matrix product with the BatchNorm (running statistics: an affine
    map per channel) and the bias folded into it, then ReLU in place; the same values as the
    three modules up to float rounding."""
    conv, norm = merge[0], merge[1]
    if norm.training or both.shape[0] != 1 or torch.is_grad_enabled():
        if bias is not None:
            both = both + bias[:, None]
        b, c2, cells = both.shape
        return merge(both.view(b, c2, cells, 1)).view(b, -1, cells)
    scale, shift = batchnorm_affine(norm)
    weight = conv.weight.view(conv.weight.shape[0], -1) * scale[:, None]
    if bias is not None:
        shift = shift + weight @ bias
    return torch.addmm(shift[:, None], weight, both[0]).relu_().unsqueeze(0)


class _CrossFusion(nn.Module):
    """Shared frame of the attention fusions: PE, per-direction attention, residual, merge."""

    def __init__(
        self,
        channels: int,
        lidar_dir: nn.Module | None,
        radar_dir: nn.Module | None,
    ) -> None:
        super().__init__()
        self.channels = channels
        self.lidar_dir = lidar_dir
        self.radar_dir = radar_dir
        self.merge = _merge(channels)

    def forward(self, f_l: Tensor, f_r: Tensor) -> Tensor:
        """``(B, C, H, W)`` LiDAR and radar maps -> ``lr`` ``(B, C, H, W)``."""
        _check_pair(f_l, f_r, self.channels)
        b, c, height, width = f_l.shape
        pe = sinusoidal_position_encoding(c, height, width, f_l.device).to(f_l.dtype)
        x_l, x_r = f_l + pe, f_r + pe
        lid, rad = self.lidar_dir, self.radar_dir
        if (
            isinstance(lid, AgentCrossAttention)
            and isinstance(rad, AgentCrossAttention)
            and lid.heads == rad.heads == 1
            and b == 1
            and f_l.device.type == "cpu"
            and not torch.is_grad_enabled()
        ):  # one-head BACA at CPU inference: the projections folded into the agents
            both = f_l.new_empty(2, c, height * width)
            for att, xa, xb, fa, out in (
                (lid, x_l, x_r, f_l, both[0]),
                (rad, x_r, x_l, f_r, both[1]),
            ):
                folded_direction(
                    att.q, att.k, att.v, att.out, att.agent_size, xa[0], xb[0].reshape(c, -1),
                    fa[0].reshape(c, -1), out,
                )  # fmt: skip
            out_bias = torch.cat([lid.out.bias, rad.out.bias])
            merged = _merged(self.merge, both.view(1, 2 * c, -1), out_bias)
            return merged.view(b, c, height, width)
        if isinstance(lid, AgentCrossAttention) and isinstance(rad, AgentCrossAttention):
            # BACA: each sensor's map feeds its own queries and the other direction's keys and
            # values, so its three projections are one product (rows: Q, K, V).
            from_l = _project_many((lid.q, rad.k, rad.v), x_l.reshape(b, c, -1))
            from_r = _project_many((rad.q, lid.k, lid.v), x_r.reshape(b, c, -1))
            shape = (b, c, height, width)
            f_lg = lid.attend(from_l[:, :c].view(shape), from_r[:, c : 2 * c], from_r[:, 2 * c :])
            f_rm = rad.attend(from_r[:, :c].view(shape), from_l[:, c : 2 * c], from_l[:, 2 * c :])
            both = torch.cat(
                [
                    f_l.reshape(b, c, -1) + _project(lid.out, f_lg),
                    f_r.reshape(b, c, -1) + _project(rad.out, f_rm),
                ],
                dim=1,
            )
            return _merged(self.merge, both).view(shape)
        lidar = f_l + self.lidar_dir(x_l, x_r) if self.lidar_dir is not None else f_l
        radar = f_r + self.radar_dir(x_r, x_l) if self.radar_dir is not None else f_r
        return self.merge(torch.cat([lidar, radar], dim=1))


class BidirectionalAgentCrossAttention(_CrossFusion):
    """BACA (eqs. 1-8): LiDAR-agent and radar-agent cross attention in both directions.

    Args:
        channels: ``C`` of the stage.
        agent_size: ``(h, w)`` of the context agents.
        heads: Attention heads (``C`` must be divisible by it).
    """

    def __init__(self, channels: int, agent_size: tuple[int, int] = (12, 12), heads: int = 1):
        super().__init__(
            channels,
            AgentCrossAttention(channels, agent_size, heads),
            AgentCrossAttention(channels, agent_size, heads),
        )


class UnidirectionalAgentCrossAttention(_CrossFusion):
    """One direction of BACA only: ``query="lidar"`` is ``L_Q + R_KV``, ``"radar"`` is ``R_Q + L_KV``."""

    def __init__(
        self,
        channels: int,
        query: str,
        agent_size: tuple[int, int] = (12, 12),
        heads: int = 1,
    ) -> None:
        if query not in ("lidar", "radar"):
            raise ValueError(f"query must be 'lidar' or 'radar', got {query!r}")
        direction = AgentCrossAttention(channels, agent_size, heads)
        super().__init__(
            channels,
            direction if query == "lidar" else None,
            direction if query == "radar" else None,
        )


class BidirectionalCrossAttention(_CrossFusion):
    """Bi-MHCA: vanilla multi-head cross attention in both directions (quadratic in cells)."""

    def __init__(self, channels: int, heads: int = 1, chunk: int = 1024) -> None:
        super().__init__(
            channels,
            VanillaCrossAttention(channels, heads, chunk),
            VanillaCrossAttention(channels, heads, chunk),
        )


class ConvGateFusion(nn.Module):
    """Convolutional gated fusion (AGN-like): ``lr = merge([g_l * f_l, g_r * f_r])`` with
    ``(g_l, g_r) = sigmoid(Conv3x3([f_l, f_r]))``, one gate map per sensor and channel."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.channels = channels
        self.gate = nn.Conv2d(2 * channels, 2 * channels, 3, padding=1)
        self.merge = _merge(channels)

    def forward(self, f_l: Tensor, f_r: Tensor) -> Tensor:
        _check_pair(f_l, f_r, self.channels)
        both = torch.cat([f_l, f_r], dim=1)
        return self.merge(torch.sigmoid(self.gate(both)) * both)


def build_fusion(cfg: FusionConfig, channels: int) -> nn.Module:
    """The fusion module of one stage for ``cfg.kind``."""
    agent = (cfg.agent_size[0], cfg.agent_size[1])
    if cfg.kind == "baca":
        return BidirectionalAgentCrossAttention(channels, agent, cfg.heads)
    if cfg.kind == "bi_mhca":
        return BidirectionalCrossAttention(channels, cfg.heads, cfg.mhca_chunk)
    if cfg.kind == "lidar_query":
        return UnidirectionalAgentCrossAttention(channels, "lidar", agent, cfg.heads)
    if cfg.kind == "radar_query":
        return UnidirectionalAgentCrossAttention(channels, "radar", agent, cfg.heads)
    if cfg.kind == "conv_gate":
        return ConvGateFusion(channels)
    raise ValueError(f"unknown fusion kind {cfg.kind!r}")
