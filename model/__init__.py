"""TPCNet: language-guided 3D visual grounding on LiDAR + 4D radar (the paper's section III).

What other packages may use (and the only names they import from ``model``)::

    build_model(preset="small", **overrides) -> TPCNet     build_config(...) -> ModelConfig
    load_checkpoint(path, device) / save_checkpoint / read_checkpoint / CheckpointError
    DEFAULT_CHECKPOINT                                      CheckpointMeta (checkpoint metadata)
    TPCNet, SceneFeatures, Predictions, as_points           LabelledBoxes (labelled candidates)
    GroundingModel, PredictionsView, GridExtent, ModelSettings   (the typed protocol, no torch)
    model_classes                            (a model's class set; vod for one without a config)
    operating_threshold(model), UNCALIBRATED_REFERENT       score_directories (the VoD metric)

and, for the benchmarks that time or count parts on their own, the names in the second group of
:data:`_EXPORTS` (the fusion and graph blocks, MiniLM, decoding, targets and losses, the
referent head and its heatmap).

``build_model`` builds a :class:`model.tpcnet.TPCNet` from a preset (:mod:`model.config`) with
overrides such as ``fusion="bi_mhca"``, ``modalities="lidar"``, ``anchor="center"``,
``text_encoder="gru"``, ``agent_size=(8, 8)``, ``graph_k=(4, 4, 2)``, ``text_fusion="ggf"`` or
``section__field=value`` (e.g. ``head__score_threshold=0.3``).

The names are loaded on first use (PEP 562), so that ``from model import GroundingModel`` does not
import torch; :data:`_EXPORTS` says where each lives. The sub-packages, bottom layer first: ``core``
(shared types: grid, anchors, labelled boxes, candidates, inputs and outputs), ``config``,
``nets`` (encoders, fusion, text), ``head`` (the detector head, targets, decoding, losses) and
``referent`` (the referent stage), ``grounding`` (the scene encoder, the grounding-head interface,
the paper's head and the referent head), then ``tpcnet``, ``training`` and ``evaluation``; the
layer order is docs/DESIGN.md's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from scenes.utils.lazy import lazy_exports

if TYPE_CHECKING:
    from model.checkpoint import (
        DEFAULT_CHECKPOINT,
        CheckpointError,
        load_checkpoint,
        read_checkpoint,
        save_checkpoint,
    )
    from model.checkpoint_meta import CheckpointMeta
    from model.config import FusionConfig, ModelConfig, build_config, preset
    from model.core.candidates import SceneMaps
    from model.core.features import Predictions, SceneFeatures, as_points
    from model.core.labelled import LabelledBoxes
    from model.evaluation.baselines import class_noun_prompt
    from model.evaluation.files import score_directories
    from model.evaluation.predict import operating_threshold
    from model.grounding.referent import UNCALIBRATED_REFERENT, referent_head
    from model.head.decode import decode
    from model.head.losses import grounding_loss
    from model.head.targets import collate_targets, draw_targets
    from model.nets.dggf import (
        dynamic_max_relative,
        dynamic_max_relative_loop,
        static_max_relative,
    )
    from model.nets.fusion import build_fusion
    from model.nets.text import load_minilm, tokenize
    from model.protocol import (
        GridExtent,
        GroundingModel,
        ModelSettings,
        PredictionsView,
        model_classes,
    )
    from model.referent.heatmap import referent_heatmap
    from model.tpcnet import TPCNet, build_model

_EXPORTS = {
    "CheckpointError": "model.checkpoint",
    "CheckpointMeta": "model.checkpoint_meta",
    "DEFAULT_CHECKPOINT": "model.checkpoint",
    "load_checkpoint": "model.checkpoint",
    "read_checkpoint": "model.checkpoint",
    "save_checkpoint": "model.checkpoint",
    "ModelConfig": "model.config",
    "score_directories": "model.evaluation.files",
    "class_noun_prompt": "model.evaluation.baselines",
    "operating_threshold": "model.evaluation.predict",
    "Predictions": "model.core.features",
    "SceneFeatures": "model.core.features",
    "as_points": "model.core.features",
    "GridExtent": "model.protocol",
    "GroundingModel": "model.protocol",
    "ModelSettings": "model.protocol",
    "PredictionsView": "model.protocol",
    "model_classes": "model.protocol",
    "UNCALIBRATED_REFERENT": "model.grounding.referent",
    "LabelledBoxes": "model.core.labelled",
    "TPCNet": "model.tpcnet",
    "build_model": "model.tpcnet",
    "build_config": "model.config",
    # The parts the benchmarks (bench/) time or count on their own:
    "FusionConfig": "model.config",
    "preset": "model.config",
    "build_fusion": "model.nets.fusion",
    "dynamic_max_relative": "model.nets.dggf",
    "dynamic_max_relative_loop": "model.nets.dggf",
    "static_max_relative": "model.nets.dggf",
    "load_minilm": "model.nets.text",
    "tokenize": "model.nets.text",
    "decode": "model.head.decode",
    "grounding_loss": "model.head.losses",
    "collate_targets": "model.head.targets",
    "draw_targets": "model.head.targets",
    "referent_head": "model.grounding.referent",
    "SceneMaps": "model.core.candidates",
    "referent_heatmap": "model.referent.heatmap",
}
"""Exported name -> the module that defines it."""

__all__ = [
    "DEFAULT_CHECKPOINT",
    "UNCALIBRATED_REFERENT",
    "CheckpointError",
    "CheckpointMeta",
    "FusionConfig",
    "GridExtent",
    "GroundingModel",
    "LabelledBoxes",
    "ModelConfig",
    "ModelSettings",
    "Predictions",
    "PredictionsView",
    "SceneFeatures",
    "SceneMaps",
    "TPCNet",
    "as_points",
    "build_config",
    "build_fusion",
    "build_model",
    "class_noun_prompt",
    "collate_targets",
    "decode",
    "draw_targets",
    "dynamic_max_relative",
    "dynamic_max_relative_loop",
    "grounding_loss",
    "load_checkpoint",
    "load_minilm",
    "model_classes",
    "operating_threshold",
    "preset",
    "read_checkpoint",
    "referent_head",
    "referent_heatmap",
    "save_checkpoint",
    "score_directories",
    "static_max_relative",
    "tokenize",
]


__getattr__ = lazy_exports(__name__, _EXPORTS)
