"""C3D-RECHead: anchor-point heatmaps and box regression (paper section III-E, eqs. 13-17, fig. 7).

The head turns the fused BEV feature map ``(B, C, H, W)`` (rows ``iy`` along +y, columns ``ix``
along +x; see :mod:`model.core.grid`) into

- ``heatmap (B, C, H, W)``: raw logits, one channel per class of the head's class set in its
  order (``HeadConfig.class_set``, :mod:`scenes.geometry.classes`; ``C = 3`` for ``vod``: Car,
  Pedestrian, Cyclist; 10 for ``nuscenes``). A box's heatmap peaks at its *anchor point* (below),
  not at its centre;
- ``regression (B, 8, H, W)``: read at the anchor cell, the channels are
  ``(dx, dy, z, log l, log w, log h, sin yaw, cos yaw)``. ``(dx, dy)`` is the offset **in metres**
  (LiDAR-frame axes) from the anchor cell's centre to the box centre; ``z`` is the box's geometric
  centre height in metres; ``l, w, h`` in metres; ``yaw`` counter-clockwise about +z from +x.

Anchor points (``HeadConfig.anchor``):

- ``"corner"`` (default): the BEV corner of the box nearest the ego vehicle (the LiDAR origin).
  Section III-F says the heatmaps "estimate the nearest corner of each detected object"; the
  surface facing the sensor carries the densest LiDAR and radar returns, and distance words in a
  prompt ("the car 5 metres ahead") refer to that near side, so a peak there is both better
  supported by the points and better aligned with the text than a peak at the (often empty) centre.
- ``"edge"``: the midpoint of the edge nearest the sensor (eq. 17: the edge ``e*`` minimising the
  Euclidean distance from the sensor to the edge segment).
- ``"center"``: the box centre, i.e. the CenterPoint head, for the ablation.

The nearest corner (or edge) of a box jumps to another one as the box's yaw or position changes,
and for a box straight ahead two corners are equally near. This does not hurt decoding: the
regression target is the offset *from whichever anchor was chosen to the centre*, expressed in the
LiDAR frame, so anchor + offset gives back the centre exactly whatever corner was used. What the
network must learn is where the peak is; when it hesitates between two equally near corners, both
peaks decode to (nearly) the same box and rotated NMS keeps one.

Architecture (after CenterPoint's CenterHead, spec section 3.7): a shared 3x3 conv + BN + ReLU,
then a heatmap branch (3x3 conv + BN + ReLU, 3x3 conv to ``C`` channels with bias -2.19, i.e. an initial
sigmoid of about 0.1) and one branch per regression group (offset 2, z 1, log size 3, sin/cos 2),
each 3x3 conv + BN + ReLU then a 3x3 conv, concatenated to 8 channels. The regression is shared by
the classes. CenterPoint's deformable convolutions (DCN) are replaced by plain convolutions:
no compiled extensions in this project.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.config import HeadConfig
from model.nets.folding import batchnorm_affine

REGRESSION_CHANNELS = 8
"""``(dx, dy, z, log l, log w, log h, sin yaw, cos yaw)``."""

REGRESSION_GROUPS: tuple[tuple[str, int], ...] = (("offset", 2), ("z", 1), ("size", 3), ("rot", 2))
"""Regression branches in channel order; their widths add up to :data:`REGRESSION_CHANNELS`."""


@dataclass(frozen=True)
class HeadOutput:
    """Raw outputs of :class:`C3DRecHead` on the head's BEV grid.

    Attributes:
        heatmap: ``(B, C, H, W)`` logits (before sigmoid), one channel per class of the set.
        regression: ``(B, 8, H, W)`` ``(dx, dy, z, log l, log w, log h, sin yaw, cos yaw)``;
            ``(dx, dy)`` in metres from the anchor cell's centre to the box centre, LiDAR frame.
    """

    heatmap: Tensor
    regression: Tensor


def _conv_bn_relu(in_channels: int, out_channels: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(in_channels, out_channels, 3, padding=1, bias=False),
        nn.BatchNorm2d(out_channels),
        nn.ReLU(inplace=True),
    )


class C3DRecHead(nn.Module):
    """The C3D-RECHead (fig. 7): shared conv, heatmap branch, regression branches.

    Args:
        cfg: Head configuration (its class set gives the heatmap's channels).
        in_channels: Channels of the input BEV feature map.
    """

    def __init__(self, cfg: HeadConfig, in_channels: int) -> None:
        super().__init__()
        if in_channels < 1:
            raise ValueError(f"C3DRecHead in_channels must be >= 1, got {in_channels}")
        self.cfg = cfg
        ch = cfg.head_channels
        self.shared = _conv_bn_relu(in_channels, ch)
        self.heatmap = nn.Sequential(
            _conv_bn_relu(ch, ch), nn.Conv2d(ch, len(cfg.class_set), 3, padding=1)
        )
        nn.init.constant_(self.heatmap[-1].bias, cfg.heatmap_bias)
        self.regression = nn.ModuleDict(
            {
                name: nn.Sequential(_conv_bn_relu(ch, ch), nn.Conv2d(ch, width, 3, padding=1))
                for name, width in REGRESSION_GROUPS
            }
        )

    def forward(self, x: Tensor) -> HeadOutput:
        """Run the head.

        Args:
            x: ``(B, C, H, W)`` BEV features on the head's grid.

        Returns:
            :class:`HeadOutput` with ``heatmap (B, C, H, W)`` and ``regression (B, 8, H, W)``.
        """
        if x.dim() != 4:
            raise ValueError(
                f"C3DRecHead expects (B, C, H, W) features, got shape {tuple(x.shape)}"
            )
        if not self.training and not torch.is_grad_enabled():
            return self._infer(x)
        shared = self.shared(x)
        heatmap = self.heatmap(shared)
        regression = torch.cat([branch(shared) for branch in self.regression.values()], dim=1)
        return HeadOutput(heatmap=heatmap, regression=regression)

    def _infer(self, x: Tensor) -> HeadOutput:
        """:meth:`forward` in eval mode without gradients: the same layers, channels-last (the
        layout oneDNN's convolutions run natively: the head's narrow maps are not reordered into
        blocks and back around every conv), each BatchNorm folded into the conv before it
        (:func:`_folded`), the five branches' first convs (all on the shared map) as one conv;
        for one item the branches' last convs by :func:`conv3x3_by_taps`; equal to float
        rounding."""
        conv, norm = self.shared[0], self.shared[1]
        weight, bias = _folded(conv.weight, [norm])
        shared = F.conv2d(x.contiguous(memory_format=torch.channels_last), weight, bias, padding=1)
        shared = shared.relu_()
        branches = [self.heatmap, *self.regression.values()]
        firsts = [branch[0] for branch in branches]  # conv (no bias), BatchNorm, ReLU each
        weight, bias = _folded(torch.cat([f[0].weight for f in firsts]), [f[1] for f in firsts])
        hidden = F.conv2d(shared, weight, bias, padding=1).relu_()
        width = self.cfg.head_channels
        if hidden.shape[0] != 1:
            outs = [
                branch[1](hidden[:, i * width : (i + 1) * width])
                for i, branch in enumerate(branches)
            ]
            return HeadOutput(
                heatmap=outs[0].contiguous(), regression=torch.cat(outs[1:], dim=1).contiguous()
            )
        # One item (the app's call): the regression branches' last convs as products per tap
        # (conv3x3_by_taps) read from the channels-last hidden map in place, written straight
        # into the output. The heatmap's stays oneDNN's convolution: an untrained head's
        # heatmap is flat, and rounding it otherwise reorders its tied peaks.
        heatmap = branches[0][1](hidden[:, :width]).contiguous()
        _, _, height, w = hidden.shape
        regression = hidden.new_empty(REGRESSION_CHANNELS, height, w)
        start = 0
        groups = zip(branches[1:], REGRESSION_GROUPS, strict=True)
        for i, (branch, (_, channels)) in enumerate(groups, start=1):
            conv = branch[1]
            block = hidden[0, i * width : (i + 1) * width]
            conv3x3_by_taps(block, conv.weight, conv.bias, regression[start : start + channels])
            start += channels
        regression = regression.unsqueeze(0)
        return HeadOutput(heatmap=heatmap, regression=regression)


def _folded(weight: Tensor, norms: list[nn.Module]) -> tuple[Tensor, Tensor]:
    """A bias-free conv's ``weight (K, C, kh, kw)`` and the BatchNorms after it (running
    statistics; their channels in order make up the ``K``) as one conv's weight and bias:
    ``BN(conv(x, w)) = conv(x, w * s) + (beta - mean * s)``, ``s = gamma / sqrt(var + eps)``.
    A BatchNorm on a channels-last map is a slow pass of its own; folded it costs nothing."""
    affine = [batchnorm_affine(n) for n in norms]
    scale = torch.cat([a for a, _ in affine])
    return weight * scale.view(-1, 1, 1, 1), torch.cat([b for _, b in affine])


def conv3x3_by_taps(x: Tensor, weight: Tensor, bias: Tensor | None, out: Tensor) -> Tensor:
    """A 3x3 convolution (stride 1, zero padding 1) of one map ``x (C, H, W)`` with ``weight
    (K, C, 3, 3)`` and ``bias (K,)`` into ``out (K, H, W)`` (contiguous), returned. ``x`` is
    read in place when it is contiguous or a channel slice of a channels-last map.

    One matrix product gives every tap's contribution at every cell, ``(9 K, C) @ (C, H W)``,
    and the nine are added at their offsets. For the head's narrow outputs (1 to 3 channels)
    this takes about half the time of oneDNN's convolution, with the same FLOPs; equal to it up
    to float rounding (the sum runs over the channels first, then the taps).
    """
    c, height, width = x.shape
    k = weight.shape[0]
    if x.is_contiguous():
        cells = x.reshape(c, height * width)
    else:  # (a channels-last slice: a transposed operand, no copy)
        cells = x.permute(1, 2, 0).reshape(height * width, c).t()
    taps = torch.mm(weight.permute(2, 3, 0, 1).reshape(9 * k, c), cells)
    taps = taps.view(3, 3, k, height, width)
    if bias is None:
        out.copy_(taps[1, 1])
    else:
        torch.add(taps[1, 1], bias.view(k, 1, 1), out=out)
    for u in range(3):
        rows = slice(max(0, 1 - u), min(height, height + 1 - u))
        from_rows = slice(rows.start + u - 1, rows.stop + u - 1)
        for v in range(3):
            if u == 1 and v == 1:
                continue
            cols = slice(max(0, 1 - v), min(width, width + 1 - v))
            from_cols = slice(cols.start + v - 1, cols.stop + v - 1)
            out[:, rows, cols].add_(taps[u, v, :, from_rows, from_cols])
    return out
