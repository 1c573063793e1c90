"""oneDNN's linear layer for frozen CPU weights (the text encoder's MiniLM, issue 20).

PyTorch exposes oneDNN's inner product to its compiler as ``torch.ops.mkldnn._linear_pointwise``
(:data:`_ONEDNN_LINEAR`): on the CPU it multiplies the few rows of one prompt by MiniLM's weight
matrices in about 60 % of the time of ``F.linear``'s BLAS call, with GELU fused into it. Given a
plain weight it reorders the weight into its blocked layout on every call;
:class:`FrozenLinear` reorders a frozen weight once (``torch.ops.mkldnn._reorder_linear_weight``)
and multiplies by that, bit for bit the same products in about half the time again.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

_ONEDNN_LINEAR = (
    getattr(torch.ops.mkldnn, "_linear_pointwise", None)
    if torch.backends.mkldnn.is_available()
    else None
)
"""oneDNN's inner product as PyTorch exposes it to its compiler (``None`` where the build has
none): on the CPU it multiplies a few prompt tokens by MiniLM's weight matrices in about 60 % of
the time of ``F.linear``'s BLAS call (a single prompt is 10-30 rows: the regime where the BLAS
kernel is least efficient)."""


def _linear(x: Tensor, weight: Tensor, bias: Tensor, gelu: bool = False) -> Tensor:
    """``F.linear(x, weight, bias)`` (then exact GELU when ``gelu``), through
    :data:`_ONEDNN_LINEAR` on CPU float32 tensors (GELU fused into it); equal to float rounding."""
    if _ONEDNN_LINEAR is not None and x.device.type == "cpu" and x.dtype == torch.float32:
        return _ONEDNN_LINEAR(x, weight, bias, "gelu" if gelu else "none", [], "none")
    y = F.linear(x, weight, bias)
    return F.gelu(y) if gelu else y


def _onednn_packed(weight: Tensor) -> Tensor | None:
    """``weight (N, K)`` reordered once into oneDNN's own blocked layout for
    :data:`_ONEDNN_LINEAR` (None where the build cannot). Given a plain weight, oneDNN reorders it
    into that layout on *every* call: for MiniLM's 42 MB of matrices that is about half the
    time of a prompt. The products are the same bit for bit (the same kernel runs on the same
    blocked weights), for any number of rows from 2 up."""
    if _ONEDNN_LINEAR is None or weight.device.type != "cpu" or weight.dtype != torch.float32:
        return None
    try:
        return torch.ops.mkldnn._reorder_linear_weight(weight, None)
    except (AttributeError, RuntimeError):  # an older build without the op
        return None


class FrozenLinear:
    """A frozen linear layer (no gradient ever flows through it): ``weight (N, K)``, ``bias
    (N,)`` and, on the CPU, the weight prepacked for oneDNN (:func:`_onednn_packed`); MiniLM's
    layers (:class:`model.nets.text.MiniLMForward`)."""

    def __init__(self, weight: Tensor, bias: Tensor) -> None:
        self.weight, self.bias = weight, bias
        self.packed = _onednn_packed(weight)

    def __call__(self, x: Tensor, gelu: bool = False) -> Tensor:
        """``(..., K) -> (..., N)``, then exact GELU when ``gelu`` (:func:`_linear`); the packed
        weight serves CPU float32 inputs of two rows or more (a single row takes oneDNN's
        vector kernel, whose rounding differs from the plain weight's)."""
        packed = self.packed
        if (
            packed is not None
            and x.device.type == "cpu"
            and x.dtype == torch.float32
            and x.numel() > x.shape[-1]
        ):
            return _ONEDNN_LINEAR(x, packed, self.bias, "gelu" if gelu else "none", [], "none")
        return _linear(x, self.weight, self.bias, gelu)


__all__ = ["FrozenLinear"]
