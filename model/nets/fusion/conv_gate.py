"""``conv_gate``: a convolutional gate in the spirit of AGN / LiRaFusion (the paper's fusion
ablations): per-sensor sigmoid gates from a 3x3 conv over both maps, then BACA's merge."""

from __future__ import annotations

import torch
from torch import Tensor, nn

from model.nets.fusion.shared import check_pair, merge_block


class ConvGateFusion(nn.Module):
    """Convolutional gated fusion (AGN-like): ``lr = merge([g_l * f_l, g_r * f_r])`` with
    ``(g_l, g_r) = sigmoid(Conv3x3([f_l, f_r]))``, one gate map per sensor and channel."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.channels = channels
        self.gate = nn.Conv2d(2 * channels, 2 * channels, 3, padding=1)
        self.merge = merge_block(channels)

    def forward(self, f_l: Tensor, f_r: Tensor) -> Tensor:
        check_pair(f_l, f_r, self.channels)
        both = torch.cat([f_l, f_r], dim=1)
        return self.merge(torch.sigmoid(self.gate(both)) * both)
