"""C3D-RECHead: anchor-point heatmaps and box regression (paper section III-E, eqs. 13-17, fig. 7).

The head turns the fused BEV feature map ``(B, C, H, W)`` (rows ``iy`` along +y, columns ``ix``
along +x; see :mod:`model.nets.grid`) into

- ``heatmap (B, 3, H, W)``: raw logits, one channel per class in the order of
  :data:`scenes.actors.CLASSES` (Car, Pedestrian, Cyclist). A box's heatmap peaks at its *anchor
  point* (below), not at its centre;
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
then a heatmap branch (3x3 conv + BN + ReLU, 3x3 conv to 3 channels with bias -2.19, i.e. an initial
sigmoid of about 0.1) and one branch per regression group (offset 2, z 1, log size 3, sin/cos 2),
each 3x3 conv + BN + ReLU then a 3x3 conv, concatenated to 8 channels. The regression is shared by
the three classes. CenterPoint's deformable convolutions (DCN) are replaced by plain convolutions:
no compiled extensions in this project.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.config import HeadConfig
from scenes.actors import CLASSES

NUM_CLASSES = len(CLASSES)
"""Heatmap channels: Car, Pedestrian, Cyclist."""

REGRESSION_CHANNELS = 8
"""``(dx, dy, z, log l, log w, log h, sin yaw, cos yaw)``."""

REGRESSION_GROUPS: tuple[tuple[str, int], ...] = (("offset", 2), ("z", 1), ("size", 3), ("rot", 2))
"""Regression branches in channel order; their widths add up to :data:`REGRESSION_CHANNELS`."""


@dataclass(frozen=True)
class HeadOutput:
    """Raw outputs of :class:`C3DRecHead` on the head's BEV grid.

    Attributes:
        heatmap: ``(B, 3, H, W)`` logits (before sigmoid), channels Car, Pedestrian, Cyclist.
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
        cfg: Head configuration.
        in_channels: Channels ``C`` of the input BEV feature map.
    """

    def __init__(self, cfg: HeadConfig, in_channels: int) -> None:
        super().__init__()
        if in_channels < 1:
            raise ValueError(f"C3DRecHead in_channels must be >= 1, got {in_channels}")
        self.cfg = cfg
        ch = cfg.head_channels
        self.shared = _conv_bn_relu(in_channels, ch)
        self.heatmap = nn.Sequential(
            _conv_bn_relu(ch, ch), nn.Conv2d(ch, NUM_CLASSES, 3, padding=1)
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
            :class:`HeadOutput` with ``heatmap (B, 3, H, W)`` and ``regression (B, 8, H, W)``.
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
        blocks and back around every conv), and the five branches' first convs (all on the
        shared map) as one conv, their BatchNorms as one; equal to float rounding."""
        shared = self.shared(x.contiguous(memory_format=torch.channels_last))
        branches = [self.heatmap, *self.regression.values()]
        firsts = [branch[0] for branch in branches]  # conv (no bias), BatchNorm, ReLU each
        norms = [first[1] for first in firsts]
        hidden = F.conv2d(shared, torch.cat([f[0].weight for f in firsts]), None, padding=1)
        hidden = F.batch_norm(
            hidden,
            torch.cat([n.running_mean for n in norms]),
            torch.cat([n.running_var for n in norms]),
            torch.cat([n.weight for n in norms]),
            torch.cat([n.bias for n in norms]),
            False,
            0.0,
            norms[0].eps,
        ).relu_()
        width = self.cfg.head_channels
        outs = [
            branch[1](hidden[:, i * width : (i + 1) * width]) for i, branch in enumerate(branches)
        ]
        return HeadOutput(
            heatmap=outs[0].contiguous(), regression=torch.cat(outs[1:], dim=1).contiguous()
        )
