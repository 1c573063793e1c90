"""The interface of a grounding head: what turns the shared scene encoder's output and a prompt's
text features into an answer. Two heads implement it (``ModelConfig.grounding``):
:class:`model.grounding.paper.PaperGrounding` (the paper's DGGF + C3D-RECHead ranking) and
:class:`model.grounding.referent.ReferentGrounding` (the referent stage over the detector's
candidates). :class:`model.tpcnet.TPCNet` holds one (chosen once, :func:`model.tpcnet.head_class`)
and never asks which: what differs between the two kinds is the head's to answer (its thresholds:
:attr:`GroundingHead.min_score`, :attr:`GroundingHead.uncalibrated_threshold`; its candidates:
:attr:`GroundingHead.takes_labelled_candidates`); how each trains is
:mod:`model.training.kinds`'s, kept per head class.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

from torch import Tensor, nn

from model.config import ModelConfig
from model.core.features import PointsLike, Predictions, SceneFeatures
from model.core.labelled import LabelledBoxes
from model.grounding.scene_encoder import SceneEncoder
from model.head.detector import HeadOutput
from model.nets.text import TextFeatures


class GroundingHead(nn.Module):
    """One grounding head (subclasses implement every method)."""

    takes_labelled_candidates: ClassVar[bool] = False
    """Whether :meth:`encode` accepts labelled boxes as the only possible answers."""
    takes_alternatives: ClassVar[bool] = False
    """Whether :meth:`answer` takes several texts of one sentence (one per class the referent
    may be: :attr:`scenes.language.reading.Reading.texts`) and answers with the best candidate
    over them; else only the first text is given."""

    @classmethod
    def build(cls, cfg: ModelConfig, text_dim: int, neck_channels: int) -> GroundingHead:
        """The head of ``cfg`` for a text encoder of ``text_dim`` features and a neck of
        ``neck_channels`` output channels."""
        raise NotImplementedError

    @property
    def min_score(self) -> float:
        """The smallest score :meth:`answer` returns when given no threshold."""
        raise NotImplementedError

    @property
    def uncalibrated_threshold(self) -> float:
        """The operating threshold of a checkpoint never calibrated (``model.training.calibrate``):
        what :func:`model.evaluation.predict.operating_threshold` falls back to."""
        raise NotImplementedError

    def encode(
        self,
        scene: SceneEncoder,
        lidar: list[Tensor] | None,
        radar: list[Tensor] | None,
        candidates: LabelledBoxes | None,
    ) -> SceneFeatures:
        """The text-independent features of one scene (checked clouds, batch 1, no gradient)."""
        raise NotImplementedError

    def check(self, scene: SceneEncoder, features: SceneFeatures) -> None:
        """Raise ValueError unless ``features`` come from :meth:`encode` of this model."""
        raise NotImplementedError

    def answer(
        self,
        scene: SceneEncoder,
        features: SceneFeatures,
        text: TextFeatures,
        prompt: str,
        score_threshold: float | None,
    ) -> Predictions:
        """The answer to one prompt (``prompt``, validated; ``text``: it encoded, batch 1) on one
        encoded scene: boxes, scores and heatmaps on ``scene.head_grid``; the text encoder's
        time is left 0 (:meth:`model.tpcnet.TPCNet.ground` adds it)."""
        raise NotImplementedError

    def forward_batch(
        self,
        scene: SceneEncoder,
        text_encoder: nn.Module,
        lidar: Sequence[PointsLike | None] | None,
        radar: Sequence[PointsLike | None] | None,
        prompts: Sequence[str],
    ) -> HeadOutput:
        """A batched, text-conditioned training pass (the paper's path only)."""
        raise NotImplementedError
