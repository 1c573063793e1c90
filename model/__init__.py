"""TPCNet: language-guided 3D visual grounding on LiDAR + 4D radar (the paper's section III).

``build_model(preset="small", **overrides)`` builds a :class:`model.tpcnet.TPCNet` from a preset
(:mod:`model.config`) with overrides such as ``fusion="bi_mhca"``, ``modalities="lidar"``,
``anchor="center"``, ``text_encoder="gru"``, ``agent_size=(8, 8)``, ``graph_k=(4, 4, 2)``,
``text_fusion="ggf"`` or ``section__field=value`` (e.g. ``head__score_threshold=0.3``).
"""

from __future__ import annotations

from typing import Any

from model.config import ModelConfig, apply_overrides, preset
from model.labelled import LabelledBoxes
from model.tpcnet import Predictions, SceneFeatures, TPCNet

__all__ = [
    "LabelledBoxes",
    "ModelConfig",
    "Predictions",
    "SceneFeatures",
    "TPCNet",
    "build_config",
    "build_model",
]


def build_config(preset_name: str = "small", **overrides: Any) -> ModelConfig:
    """The preset's :class:`ModelConfig` with ``overrides`` applied (see the module docstring)."""
    return apply_overrides(preset(preset_name), **overrides)


def build_model(preset: str = "small", **overrides: Any) -> TPCNet:
    """A freshly initialised :class:`TPCNet` for ``preset`` (``small`` or ``paper``) + overrides."""
    return TPCNet(build_config(preset, **overrides))
