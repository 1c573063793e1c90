"""SECOND-style 2D backbone over a pillar canvas: three stages per sensor (section III-B, fig. 3).

Stage ``i`` is a strided 3x3 conv (stride 2 by default) followed by ``layers[i]`` 3x3 convs, each
conv without bias + BatchNorm + ReLU, as SECOND/PointPillars (spec section 3.3). On the paper
preset's 320 x 320 canvas the stages give ``f_1`` 64 x 160 x 160, ``f_2`` 128 x 80 x 80 and
``f_3`` 256 x 40 x 40; on the small preset's 160 x 160 canvas they are 80, 40 and 20 cells wide.

Choice: BatchNorm momentum 0.1 (PyTorch's default) rather than SECOND's 0.01, so that the running
statistics used in eval mode settle within the short trainings a CPU allows.
"""

from __future__ import annotations

from torch import Tensor, nn

from model.config import BackboneConfig


def conv_bn_relu(in_channels: int, out_channels: int, stride: int = 1) -> nn.Sequential:
    """3x3 conv (no bias) + BatchNorm2d (eps 1e-3) + ReLU."""
    return nn.Sequential(
        nn.Conv2d(in_channels, out_channels, 3, stride=stride, padding=1, bias=False),
        nn.BatchNorm2d(out_channels, eps=1e-3),
        nn.ReLU(inplace=True),
    )


class SecondBackbone(nn.Module):
    """Three-stage backbone of one sensor.

    Args:
        in_channels: Channels of the pillar canvas.
        cfg: Stage widths, extra layers and strides.
    """

    def __init__(self, in_channels: int, cfg: BackboneConfig) -> None:
        super().__init__()
        stages = []
        c_in = in_channels
        for c_out, n_layers, stride in zip(cfg.channels, cfg.layers, cfg.strides, strict=True):
            layers = [conv_bn_relu(c_in, c_out, stride)]
            layers += [conv_bn_relu(c_out, c_out) for _ in range(n_layers)]
            stages.append(nn.Sequential(*layers))
            c_in = c_out
        self.stages = nn.ModuleList(stages)
        self.out_channels: tuple[int, ...] = tuple(cfg.channels)
        self.strides: tuple[int, ...] = cfg.cumulative_strides

    def forward(self, canvas: Tensor) -> tuple[Tensor, ...]:
        """``(B, C0, H, W)`` canvas -> ``(f_1, f_2, f_3)``, ``f_i`` of shape ``(B, C_i, H/s_i, W/s_i)``."""
        outs = []
        x = canvas
        for stage in self.stages:
            x = stage(x)
            outs.append(x)
        return tuple(outs)
