"""LiDAR-radar fusion: the paper's BACA and the alternatives of its fusion ablations (tables V, VI,
VIII), one module per kind (``FusionConfig.kind``), and :func:`build_fusion`, the one place a kind
is chosen.

Every fusion has the same call: ``fusion(f_l, f_r) -> lr`` with ``f_l, f_r, lr`` of shape
``(B, C, H, W)`` (one backbone stage; one module per stage), and the same merge of the two
enriched maps (:mod:`model.nets.fusion.baca` says why), so that only the attention differs:

- ``baca`` (:mod:`~model.nets.fusion.baca`, its CPU inference forms in
  :mod:`~model.nets.fusion.baca_cpu`): Bidirectional Agent Cross Attention (section III-C);
- ``bi_mhca`` (:mod:`~model.nets.fusion.bi_mhca`): vanilla multi-head cross attention both ways;
- ``lidar_query`` / ``radar_query`` (:mod:`~model.nets.fusion.one_direction`): one direction of
  BACA;
- ``conv_gate`` (:mod:`~model.nets.fusion.conv_gate`): a convolutional gate;
- :mod:`~model.nets.fusion.shared`: the position encoding, projections, merge and the attention
  fusions' frame.

A new kind: its module here, its name in ``model.config.sections.FusionKind``, its line in
:data:`FUSIONS`. Single-modality models do not build a fusion module: ``lr`` is the sensor's own
features.
"""

from __future__ import annotations

from collections.abc import Callable

from torch import nn

from model.config import FusionConfig
from model.nets.fusion.baca import BidirectionalAgentCrossAttention
from model.nets.fusion.bi_mhca import BidirectionalCrossAttention
from model.nets.fusion.conv_gate import ConvGateFusion
from model.nets.fusion.one_direction import UnidirectionalAgentCrossAttention


def _agents(cfg: FusionConfig) -> tuple[int, int]:
    return (cfg.agent_size[0], cfg.agent_size[1])


FUSIONS: dict[str, Callable[[FusionConfig, int], nn.Module]] = {
    "baca": lambda cfg, c: BidirectionalAgentCrossAttention(c, _agents(cfg), cfg.heads),
    "bi_mhca": lambda cfg, c: BidirectionalCrossAttention(c, cfg.heads, cfg.mhca_chunk),
    "lidar_query": lambda cfg, c: UnidirectionalAgentCrossAttention(
        c, "lidar", _agents(cfg), cfg.heads
    ),
    "radar_query": lambda cfg, c: UnidirectionalAgentCrossAttention(
        c, "radar", _agents(cfg), cfg.heads
    ),
    "conv_gate": lambda cfg, c: ConvGateFusion(c),
}
"""Fusion kind -> ``(its config, the stage's channels) -> its module``."""


def build_fusion(cfg: FusionConfig, channels: int) -> nn.Module:
    """The fusion module of one stage for ``cfg.kind`` (:data:`FUSIONS`)."""
    build = FUSIONS.get(cfg.kind)
    if build is None:
        raise ValueError(f"unknown fusion kind {cfg.kind!r}")
    return build(cfg, channels)


__all__ = [
    "FUSIONS",
    "BidirectionalAgentCrossAttention",
    "BidirectionalCrossAttention",
    "ConvGateFusion",
    "UnidirectionalAgentCrossAttention",
    "build_fusion",
]
