"""The two presets, ``small`` and ``paper`` (see :mod:`model.config`)."""

from __future__ import annotations

from typing import Any

from model.config.errors import ConfigError
from model.config.sections import (
    BackboneConfig,
    FpnConfig,
    FusionConfig,
    HeadConfig,
    ModelConfig,
    PillarConfig,
    TextFusionConfig,
)
from model.config.serial import apply_overrides
from model.core.grid import BevGrid


def small_config() -> ModelConfig:
    """The CPU preset (see the module docstring)."""
    return ModelConfig()


def paper_config() -> ModelConfig:
    """The paper's sizes (see the module docstring); meant for a GPU."""
    return ModelConfig(
        pillars=PillarConfig(grid=BevGrid(0.0, 51.2, -25.6, 25.6, 0.16), channels=64),
        backbone=BackboneConfig(channels=(64, 128, 256), layers=(3, 5, 5)),
        fusion=FusionConfig(heads=4),
        text_fusion=TextFusionConfig(ffn_ratio=4),
        fpn=FpnConfig(out_channels=(128, 128, 128), output_stride=4),
        head=HeadConfig(head_channels=64),
    )


PRESETS = {"small": small_config, "paper": paper_config}


def preset(name: str) -> ModelConfig:
    """The named preset (``small`` or ``paper``)."""
    if name not in PRESETS:
        raise ConfigError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}")
    return PRESETS[name]()


def build_config(preset_name: str = "small", **overrides: Any) -> ModelConfig:
    """The preset's :class:`ModelConfig` with ``overrides`` applied (:func:`model.config.serial.
    apply_overrides`: ``fusion="bi_mhca"``, ``section__field=value``, ...)."""
    return apply_overrides(preset(preset_name), **overrides)
