"""SECOND-FPN neck over the three text-conditioned stages ``lc_i`` (section III-A: "refined via a
Feature Pyramid Network", producing ``f_i``; IV-A: "SECOND FPN").

Every stage is brought to the resolution of the neck's output (``FpnConfig.output_stride`` relative
to the pillar grid) and to ``out_channels[i]`` channels, then the three maps are concatenated:

- a finer stage (stride ``s`` < output stride ``S``): conv with kernel = stride = ``S / s``;
- the equal stage: 1x1 conv (SECOND-FPN's ``use_conv_for_no_stride``);
- a coarser stage: transposed conv with kernel = stride = ``s / S``;

each followed by BatchNorm + ReLU (spec section 3.6). The small preset uses output stride 2 (all
stages to stage-1 resolution, 80 x 80 cells of 0.64 m); the paper preset uses 4, i.e. Talk2Radar's
CenterPoint ``upsample_strides = [0.5, 1, 2]`` giving 384 x 80 x 80 on the 320 x 320 grid.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from model.config import FpnConfig


class SecondFpn(nn.Module):
    """Resample three stages to one grid and concatenate.

    Args:
        in_channels: Widths of the three input stages.
        strides: Strides of the three stages relative to the pillar grid, e.g. ``(2, 4, 8)``.
        cfg: Output widths and output stride.
    """

    def __init__(self, in_channels: Sequence[int], strides: Sequence[int], cfg: FpnConfig) -> None:
        super().__init__()
        if cfg.output_stride not in strides:
            raise ValueError(
                f"FPN output stride {cfg.output_stride} not in stage strides {strides}"
            )
        blocks = []
        for c_in, c_out, stride in zip(in_channels, cfg.out_channels, strides, strict=True):
            if stride < cfg.output_stride:
                k = cfg.output_stride // stride
                conv: nn.Module = nn.Conv2d(c_in, c_out, k, stride=k, bias=False)
            elif stride == cfg.output_stride:
                conv = nn.Conv2d(c_in, c_out, 1, bias=False)
            else:
                k = stride // cfg.output_stride
                conv = nn.ConvTranspose2d(c_in, c_out, k, stride=k, bias=False)
            blocks.append(
                nn.Sequential(conv, nn.BatchNorm2d(c_out, eps=1e-3), nn.ReLU(inplace=True))
            )
        self.blocks = nn.ModuleList(blocks)
        self.out_channels = int(sum(cfg.out_channels))
        self.output_stride = cfg.output_stride

    def forward(self, stages: Sequence[Tensor]) -> Tensor:
        """``(lc_1, lc_2, lc_3)`` -> ``(B, sum(out_channels), H / S, W / S)``."""
        return torch.cat([block(x) for block, x in zip(self.blocks, stages, strict=True)], dim=1)
