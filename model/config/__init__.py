"""Configuration of TPCNet: frozen dataclasses, one per part, nested in :class:`ModelConfig`.

Every option the paper's ablations compare is a field here, not a fork of the code:

- ``modalities``: ``"lidar"``, ``"radar"`` or ``"both"`` (tables I, III, IV).
- ``fusion.kind``: the LiDAR-radar fusion, ``"baca"`` (section III-C) or the alternatives of tables V
  and VIII: ``"bi_mhca"`` (bidirectional vanilla multi-head cross attention), ``"lidar_query"`` and
  ``"radar_query"`` (one direction of BACA only) and ``"conv_gate"`` (a convolutional gate in the
  spirit of AGN).
- ``fusion.agent_size``: the context-agent map ``h x w`` (default 12 x 12, section IV-A; table VI).
- ``text_fusion.kind``: ``"dggf"`` (section III-D) or ``"ggf"`` (Talk2Radar's static gated graph
  fusion, table IX); ``text_fusion.graph_k``: the roll step ``K`` per stage (default 8, 4, 2).
- ``head.anchor``: ``"corner"``, ``"edge"`` or ``"center"`` (table VII), see :mod:`model.head.detector`.
- ``text.encoder``: ``"minilm"`` (frozen, pretrained) or ``"gru"`` (Bi-GRU from scratch, table IX).
- ``head.classes`` (override ``classes=``): the class set, ``"vod"`` (Car, Pedestrian, Cyclist;
  the default and the shipped checkpoint's) or ``"nuscenes"`` (nuScenes' 10 detection classes),
  :mod:`scenes.geometry.classes`; every part of the model follows it (``ModelConfig.class_set``).
- ``grounding``: ``"tpcnet"`` (the paper: DGGF conditions the BEV on the sentence and the C3D-RECHead
  heatmap ranks the referred boxes) or ``"referent"`` (Talk2PC: a text-agnostic C3D-RECHead proposes
  every object and :mod:`model.referent.stage` scores each candidate against the prompt's tokens;
  ``referent`` holds its sizes). ``ModelConfig()`` keeps the paper's path; the training command
  line defaults to ``referent``, the product's path.

Two presets (:func:`preset`):

- ``small``: 0.32 m pillars, 160 x 160 over x in [0, 51.2], y in [-25.6, 25.6], z in [-3, 2]; PFN
  32, backbone 32/48/64 with 1/2/2 extra layers, neck 3 x 24, head 24, one attention head: about
  0.6 M parameters and 2.7 GFLOP per scene + prompt. The neck brings all stages to stage-1
  resolution (80 x 80, 0.64 m cells). Measured on the 2-core development CPU (idle, 60 k LiDAR +
  800 radar points): ``encode_scene`` about 45 ms, ``ground`` about 23 ms on a cached prompt and
  31 ms on a new one; a training step at batch 4 about 0.8 s.
- ``paper``: 0.16 m pillars, 320 x 320 over the same range, PFN 64, SECOND backbone widths
  64/128/256 with 3/5/5 layers, SECOND-FPN 128/128/128 with upsample strides 0.5/1/2 as in
  Talk2Radar's CenterPoint configuration (80 x 80 head grid, 0.64 m cells).

Both presets keep the paper's caps of 32 points per LiDAR pillar and 10 per radar pillar (IV-A) and
Talk2Radar's 30-token text limit.

Serialisation: :meth:`ModelConfig.to_dict` gives plain Python types (dicts, lists, str, int,
float, bool), :meth:`ModelConfig.from_dict` rebuilds the config and raises :class:`ConfigError`
naming the dotted field (e.g. ``fusion.agent_size``) on an unknown, missing or mistyped field.

Modules: ``sections`` (the dataclasses, :class:`HeadConfig` among them, and the ``Literal`` kinds
the command lines take their choices from), ``serial`` (plain data and back, overrides),
``presets`` and ``errors``; this package exports them all.
"""

from __future__ import annotations

from model.config.errors import ConfigError
from model.config.presets import PRESETS, build_config, paper_config, preset, small_config
from model.config.sections import (
    ANCHORS,
    LIDAR_FEATURES,
    RADAR_FEATURES,
    AnchorKind,
    BackboneConfig,
    ClassSetName,
    FpnConfig,
    FusionConfig,
    FusionKind,
    GroundingKind,
    HeadConfig,
    Modalities,
    ModelConfig,
    PillarConfig,
    PresetName,
    ReferentConfig,
    TextConfig,
    TextEncoderKind,
    TextFusionConfig,
    TextFusionKind,
)
from model.config.serial import ALIASES, apply_overrides, from_plain, to_plain

__all__ = [
    "ALIASES",
    "ANCHORS",
    "LIDAR_FEATURES",
    "PRESETS",
    "RADAR_FEATURES",
    "AnchorKind",
    "BackboneConfig",
    "ClassSetName",
    "ConfigError",
    "FpnConfig",
    "FusionConfig",
    "FusionKind",
    "GroundingKind",
    "HeadConfig",
    "Modalities",
    "ModelConfig",
    "PillarConfig",
    "PresetName",
    "ReferentConfig",
    "TextConfig",
    "TextEncoderKind",
    "TextFusionConfig",
    "TextFusionKind",
    "apply_overrides",
    "build_config",
    "from_plain",
    "paper_config",
    "preset",
    "small_config",
    "to_plain",
]
