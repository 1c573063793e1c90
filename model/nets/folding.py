"""A BatchNorm with its running statistics (eval mode) as the affine map it then is: the one
home of the formula that the inference forms fold into the product before it (the head's and
the fusion merge's convolutions, the pillar encoder's compiled pass)."""

from __future__ import annotations

import torch
from torch import Tensor, nn


def batchnorm_affine(norm: nn.modules.batchnorm._BatchNorm) -> tuple[Tensor, Tensor]:
    """``(scale, shift)``, each ``(C,)``, with ``norm(x) = x * scale + shift`` per channel in eval
    mode: ``scale = gamma / sqrt(var + eps)``, ``shift = beta - mean * scale``."""
    scale = norm.weight / torch.sqrt(norm.running_var + norm.eps)
    return scale, norm.bias - norm.running_mean * scale


__all__ = ["batchnorm_affine"]
