"""TPCNet (fig. 3, section III-A): the shared scene encoder (:mod:`model.grounding.scene_encoder`), the text
encoder and one grounding head (:mod:`model.grounding.interface`), assembled from a
:class:`model.config.ModelConfig`; ``cfg.grounding`` picks the head: ``tpcnet`` the paper's DGGF
+ C3D-RECHead ranking (:mod:`model.grounding.paper`), ``referent`` the referent stage over the
detector's candidates (:mod:`model.grounding.referent`).

The sensor branches and the LiDAR-radar fusion do not depend on the text, so the model splits in
two calls for the app: :meth:`TPCNet.encode_scene` (once per scene) and :meth:`TPCNet.ground`
(once per prompt, from the cached :class:`SceneFeatures`). :meth:`TPCNet.forward` runs both on a
batch for training the paper's path; in eval mode ``ground(encode_scene(l, r), p)`` gives the same
head outputs as ``forward([l], [r], [p])`` (every normalisation is per sample or in
running-statistics mode).

Input rules: :mod:`model.core.features` (NaN or inf raise :class:`NonFiniteInputError`, a missing
required sensor :class:`MissingSensorError`). ``encode_scene``/``ground`` run under
``torch.no_grad`` and do not switch the mode: call ``model.eval()`` first for inference.

Checkpoint names: the state dict keeps the names checkpoints have always had (``lidar.``,
``radar.``, ``fusion.``, ``text_encoder.``, ``text_fusion.``, ``neck.``, ``head.``,
``referent.``, in that order); :data:`CHECKPOINT_NAMES` maps them to the modules
(``scene.lidar.``, ..., ``grounding.text_fusion.``, ``grounding.stage.``) on the way out
(``state_dict``) and in (``load_state_dict``, which takes either form).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from model.checkpoint_meta import CheckpointMeta
from model.config import GroundingKind, ModelConfig, build_config
from model.core.candidates import SceneMaps
from model.core.features import (
    Clock,
    GroundTimings,
    MissingSensorError,
    NonFiniteInputError,
    PointsLike,
    Predictions,
    SceneFeatures,
    SceneTimings,
    as_points,
)
from model.core.labelled import LabelledBoxes
from model.grounding.interface import GroundingHead
from model.grounding.paper import PaperGrounding
from model.grounding.referent import ReferentGrounding
from model.grounding.scene_encoder import SceneEncoder
from model.head.detector import HeadOutput
from model.nets.text import build_text_encoder, validate_prompt
from scenes.geometry.classes import ClassSet
from scenes.geometry.ground import GroundPlane, level_clouds, level_points, unlevel_boxes
from scenes.language.reading import Reading, read_prompt

CHECKPOINT_NAMES = {
    "lidar": "scene.lidar",
    "radar": "scene.radar",
    "fusion": "scene.fusion",
    "text_encoder": "text_encoder",
    "text_fusion": "grounding.text_fusion",
    "neck": "scene.neck",
    "head": "scene.head",
    "referent": "grounding.stage",
}
"""Checkpoint name of each top-level part -> its module path, in the checkpoints' order."""

_MODULE_NAMES = {module: saved for saved, module in CHECKPOINT_NAMES.items()}
_ORDER = {saved: i for i, saved in enumerate(CHECKPOINT_NAMES)}


def checkpoint_name(name: str) -> str:
    """The checkpoint name of a parameter or buffer named ``name`` in the module tree."""
    for module, saved in _MODULE_NAMES.items():
        if name.startswith(module + "."):
            return saved + name[len(module) :]
    return name


def module_name(name: str) -> str:
    """The module-tree name of a checkpoint name (a module-tree name is returned as it is)."""
    top, _, rest = name.partition(".")
    return f"{CHECKPOINT_NAMES[top]}.{rest}" if top in CHECKPOINT_NAMES and rest else name


def _checkpoint_rank(name: str) -> int:
    return _ORDER.get(name.partition(".")[0], len(_ORDER))


def _save_checkpoint_names(
    module: nn.Module, state: dict[str, Any], prefix: str, local_metadata: Any
) -> None:
    items = [(k, state.pop(k)) for k in list(state) if k.startswith(prefix)]
    renamed = [(checkpoint_name(k[len(prefix) :]), v) for k, v in items]
    renamed.sort(key=lambda kv: _checkpoint_rank(kv[0]))
    for k, v in renamed:
        state[prefix + k] = v


def _load_checkpoint_names(
    module: nn.Module, state: dict[str, Any], prefix: str, *args: Any
) -> None:
    for key in [k for k in state if k.startswith(prefix)]:
        new = prefix + module_name(key[len(prefix) :])
        if new != key:
            state[new] = state.pop(key)


def head_class(grounding: GroundingKind) -> type[GroundingHead]:
    """The grounding head of ``grounding`` (``ModelConfig.grounding``): the one place the kinds
    are told apart. What differs between them (thresholds, candidates, how they train) is asked
    of the head (:class:`model.grounding.interface.GroundingHead`) or, for training, of the strategy
    kept for its class (:mod:`model.training.kinds`)."""
    return ReferentGrounding if grounding == "referent" else PaperGrounding


class TPCNet(nn.Module):
    """The TPCNet model. Build it with :func:`model.build_model` or ``TPCNet(ModelConfig(...))``."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.scene = SceneEncoder(cfg)
        self.grid = self.scene.grid
        self.head_grid = self.scene.head_grid
        self.text_encoder = build_text_encoder(cfg.text)
        text_dim = self.text_encoder.out_dim
        self.grounding: GroundingHead = head_class(cfg.grounding).build(
            cfg, text_dim, self.scene.neck.out_channels
        )
        self.register_state_dict_post_hook(_save_checkpoint_names)
        self.register_load_state_dict_pre_hook(_load_checkpoint_names)
        self.checkpoint_metadata = CheckpointMeta()
        """Metadata of the checkpoint this model was loaded from (see :mod:`model.checkpoint`)."""

    @property
    def device(self) -> torch.device:
        return next(self.parameters()).device

    @property
    def takes_labelled_candidates(self) -> bool:
        """Whether :meth:`encode_scene` accepts labelled boxes as the only possible answers
        (the head's :attr:`GroundingHead.takes_labelled_candidates`)."""
        return self.grounding.takes_labelled_candidates

    def parameters_in_checkpoint_order(self) -> list[nn.Parameter]:
        """The parameters in the order of their checkpoint names (:data:`CHECKPOINT_NAMES`):
        the order of the optimiser's state in ``train_state.pt``."""
        named = list(self.named_parameters())
        ranked = sorted(
            range(len(named)), key=lambda i: _checkpoint_rank(checkpoint_name(named[i][0]))
        )
        return [named[i][1] for i in ranked]

    def detect(
        self, lidar: list[Tensor] | None, radar: list[Tensor] | None
    ) -> tuple[HeadOutput, list[SceneMaps]]:
        """The text-agnostic detector on a batch of clouds (:meth:`SceneEncoder.detect`)."""
        return self.scene.detect(lidar, radar)

    def encode_scene(
        self,
        lidar: PointsLike | None = None,
        radar: PointsLike | None = None,
        candidates: LabelledBoxes | None = None,
    ) -> SceneFeatures:
        """Text-independent features of one scene (sensor branches + LiDAR-radar fusion; with
        ``grounding="referent"`` also the text-agnostic detections as candidates).

        Args:
            lidar: ``(N, 4)`` LiDAR points (x, y, z, intensity), LiDAR frame; ignored (may be
                ``None``) by a radar-only model.
            radar: ``(M, 7)`` radar points in the LiDAR frame; ignored by a LiDAR-only model.
            candidates: Referent path only: the frame's labelled boxes, among which the referent
                stage then chooses instead of the detector's proposals (each with its label's
                class and a certain score, :data:`model.core.labelled.LABELLED_SCORE`), of the
                model's class set (``cfg.class_set``).

        Returns:
            :class:`SceneFeatures` with ``lr_i`` of shape ``(1, C_i, H_i, W_i)``.
        """
        if candidates is not None and not self.takes_labelled_candidates:
            raise ValueError(
                "labelled candidates need a referent-path model; the paper's path ranks "
                "its own heatmap peaks"
            )
        if candidates is not None and candidates.classes.name != self.cfg.class_set.name:
            raise ValueError(
                f"labelled candidates of the {candidates.classes.name!r} class set given to a "
                f"model of the {self.cfg.class_set.name!r} class set"
            )
        plane = None
        if self.cfg.pillars.levels_on_ground and lidar is not None:
            lidar, radar, candidates, plane = self._levelled(lidar, radar, candidates)
        lidar_t = self.scene.clouds(None if lidar is None else [lidar], 1, "lidar")
        radar_t = self.scene.clouds(None if radar is None else [radar], 1, "radar")
        with torch.no_grad():
            features = self.grounding.encode(self.scene, lidar_t, radar_t, candidates)
        if plane is None or features.objects is None:
            return features
        height = self.cfg.pillars.ground_height
        objects = replace(
            features.objects, boxes=unlevel_boxes(features.objects.boxes, plane, height)
        )
        return replace(features, objects=objects)

    def _levelled(
        self,
        lidar: PointsLike,
        radar: PointsLike | None,
        candidates: LabelledBoxes | None,
    ) -> tuple[np.ndarray, np.ndarray | None, LabelledBoxes | None, GroundPlane]:
        """The clouds and labelled boxes with heights above the ground estimated from ``lidar``
        (``cfg.pillars.levels_on_ground``), and that plane."""
        height = self.cfg.pillars.ground_height
        radar_np = None if radar is None else _numpy(radar)
        plane, lidar_np, radar_np = level_clouds(_numpy(lidar), radar_np, height)
        if candidates is not None:
            boxes = level_points(candidates.boxes, plane, height)
            candidates = LabelledBoxes(boxes, candidates.labels, candidates.classes)
        return lidar_np, radar_np, candidates, plane

    def ground(
        self,
        features: SceneFeatures,
        prompt: str,
        score_threshold: float | None = None,
        ranked: bool = False,
    ) -> Predictions:
        """Answer one prompt on an encoded scene.

        Args:
            features: From :meth:`encode_scene` of this model.
            prompt: The referring sentence (non-empty; longer than the token limit is truncated
                and reported in :attr:`Predictions.truncated`).
            score_threshold: Smallest score returned. Default: the head's ``min_score``
                (``cfg.head.score_threshold`` for the paper's path, a decoded heatmap peak;
                ``cfg.referent.min_score`` for the referent stage, a referent probability); the
                returned *set* at the checkpoint's operating threshold is
                :func:`model.evaluation.predict.operating_threshold`'s business.
            ranked: Every candidate above the threshold in score order, as the head ranks
                them, without the sentence's number (a singular description or a command is
                otherwise answered with its best box only, :attr:`Reading.single`).

        Returns:
            :class:`Predictions` (boxes, scores, class names, sigmoid heatmaps, grid, timings).
        """
        text_prompt = validate_prompt(prompt)
        self.grounding.check(self.scene, features)
        reading = read_prompt(text_prompt, self.cfg.class_set)
        texts = reading.texts if self.grounding.takes_alternatives else reading.texts[:1]
        clock = Clock(self.device)
        with torch.no_grad():
            text = self.text_encoder(list(texts))
            t_text = clock.lap()
            answer = self.grounding.answer(self.scene, features, text, text_prompt, score_threshold)
            if reading.command and not len(answer.boxes) and reading.classes:
                # a command means one object: the best candidate of its classes, however low
                wide = self.grounding.answer(self.scene, features, text, text_prompt, 0.0)
                rows = [i for i, c in enumerate(wide.classes) if c in reading.classes]
                answer = wide.pick(rows[:1])
        if reading.single and not ranked:
            answer = answer.pick(range(min(1, len(answer.boxes))))
        note = answer_note(reading, answer.classes, self.cfg.class_set)
        answer = replace(answer, reading=reading, note=note)
        return replace(answer, timings=replace(answer.timings, text=t_text))

    def forward(
        self,
        lidar: Sequence[PointsLike | None] | None,
        radar: Sequence[PointsLike | None] | None,
        prompts: Sequence[str],
    ) -> HeadOutput:
        """Batched training/evaluation pass of the paper's path (``grounding="tpcnet"``).

        Args:
            lidar: ``B`` LiDAR clouds ``(N_b, 4)`` (``None`` for a radar-only model).
            radar: ``B`` radar clouds ``(M_b, 7)`` in the LiDAR frame (``None`` for LiDAR-only).
            prompts: ``B`` prompts.

        Returns:
            :class:`model.head.detector.HeadOutput` with ``heatmap (B, 3, H, W)`` logits and
            ``regression (B, 8, H, W)`` on :attr:`head_grid`; train it with
            :func:`model.head.losses.grounding_loss`. The referent path trains through
            :meth:`detect` and its head (:mod:`model.training.referent_step`).
        """
        return self.grounding.forward_batch(self.scene, self.text_encoder, lidar, radar, prompts)


__all__ = [
    "CHECKPOINT_NAMES",
    "GroundTimings",
    "MissingSensorError",
    "NonFiniteInputError",
    "Predictions",
    "SceneFeatures",
    "SceneTimings",
    "TPCNet",
    "as_points",
    "head_class",
]


def answer_note(reading: Reading, answered: Sequence[str], classes: ClassSet) -> str:
    """A sentence for the person when the answer is not what the sentence asked for: a class the
    model does not know, or a command whose object is not there; "" otherwise."""
    if reading.missing:
        return f"No {reading.missing} here: this model finds {classes.plural_list()} only."
    if reading.command and not answered:
        named = [classes.get(c).noun for c in reading.classes]
        what = " or ".join(named) if 0 < len(named) <= 2 else "road user of that kind"
        return f"No {what} here to carry out the command."
    return ""


def _numpy(points: PointsLike) -> np.ndarray:
    """A cloud as a float32 array (a tensor moved to the CPU)."""
    if isinstance(points, Tensor):
        return points.detach().cpu().numpy().astype(np.float32, copy=False)
    return np.asarray(points, dtype=np.float32)


def build_model(preset: str = "small", **overrides: Any) -> TPCNet:
    """A freshly initialised :class:`TPCNet` for ``preset`` (``small`` or ``paper``) + overrides
    (:func:`model.config.build_config`)."""
    return TPCNet(build_config(preset, **overrides))
