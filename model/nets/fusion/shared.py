"""What the fusions share (:mod:`model.nets.fusion`): the fixed 2D position encoding, the checked
call, the attention projections, the merge of the two enriched maps, and :class:`CrossFusion`, the
frame of the attention fusions (BACA, one-direction BACA, Bi-MHCA)."""

from __future__ import annotations

import math
from functools import lru_cache

import torch
from torch import Tensor, nn

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


def attention(q: Tensor, k: Tensor, v: Tensor) -> Tensor:
    """Softmax attention ``softmax(q k^T / sqrt(d)) v`` on ``(B, heads, N, d)`` tensors."""
    scores = torch.matmul(q, k.transpose(-1, -2)) * (q.shape[-1] ** -0.5)
    return torch.matmul(scores.softmax(dim=-1), v)


def check_pair(f_l: Tensor, f_r: Tensor, channels: int) -> None:
    """Raise ValueError unless the LiDAR and radar maps are both ``(B, channels, H, W)``."""
    if f_l.shape != f_r.shape or f_l.shape[1] != channels:
        raise ValueError(
            f"fusion expects two (B, {channels}, H, W) maps, got {tuple(f_l.shape)} "
            f"and {tuple(f_r.shape)}"
        )


class Projections(nn.Module):
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


def project_many(linears: tuple[nn.Linear, ...], x: Tensor) -> Tensor:
    """Several ``nn.Linear`` of one input in one product: channel-major ``(B, C_in, L)`` ->
    ``(B, sum C_out, L)``, the outputs stacked along the channels in the order given."""
    weight = torch.cat([lin.weight for lin in linears])
    bias = torch.cat([lin.bias for lin in linears])
    if x.shape[0] == 1:  # one matrix product with the bias as its added term
        return torch.addmm(bias[:, None], weight, x[0]).unsqueeze(0)
    return torch.matmul(weight, x) + bias[:, None]


def project(linear: nn.Linear, x: Tensor) -> Tensor:
    """``linear`` over the channels of a channel-major ``(B, C_in, L)`` tensor: ``(B, C_out, L)``."""
    return project_many((linear,), x)


def merge_block(channels: int) -> nn.Sequential:
    """The merge of the two enriched maps: 1x1 conv ``2 C -> C``, BatchNorm, ReLU."""
    return nn.Sequential(
        nn.Conv2d(2 * channels, channels, 1, bias=False),
        nn.BatchNorm2d(channels, eps=1e-3),
        nn.ReLU(inplace=True),
    )


def merged(merge: nn.Sequential, both: Tensor, bias: Tensor | None = None) -> Tensor:
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


class CrossFusion(nn.Module):
    """Shared frame of the attention fusions: PE, per-direction attention, residual, merge.

    ``lidar_dir(x_l, x_r)`` (LiDAR queries, radar keys and values) and ``radar_dir(x_r, x_l)``
    map the position-encoded maps to ``(B, C, H, W)``; a direction that is None leaves its sensor's
    map unchanged. A fusion with a faster form of the same arithmetic overrides :meth:`fuse`.
    """

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
        self.merge = merge_block(channels)

    def forward(self, f_l: Tensor, f_r: Tensor) -> Tensor:
        """``(B, C, H, W)`` LiDAR and radar maps -> ``lr`` ``(B, C, H, W)``."""
        check_pair(f_l, f_r, self.channels)
        _, c, height, width = f_l.shape
        pe = sinusoidal_position_encoding(c, height, width, f_l.device).to(f_l.dtype)
        return self.fuse(f_l, f_r, f_l + pe, f_r + pe)

    def fuse(self, f_l: Tensor, f_r: Tensor, x_l: Tensor, x_r: Tensor) -> Tensor:
        """``lr`` of the maps ``f_l, f_r`` and their position-encoded forms ``x_l, x_r``."""
        lidar = f_l + self.lidar_dir(x_l, x_r) if self.lidar_dir is not None else f_l
        radar = f_r + self.radar_dir(x_r, x_l) if self.radar_dir is not None else f_r
        return self.merge(torch.cat([lidar, radar], dim=1))
