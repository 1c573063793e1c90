"""The interface of a grounding head: what turns the shared scene encoder's output and a prompt's
text features into an answer. Two heads implement it (``ModelConfig.grounding``):
:class:`model.grounding.paper.PaperGrounding` (the paper's DGGF + C3D-RECHead ranking) and
:class:`model.grounding.referent.ReferentGrounding` (the referent stage over the detector's
candidates). :class:`model.tpcnet.TPCNet` holds one and never asks which.
"""

from __future__ import annotations

from collections.abc import Sequence

from torch import Tensor, nn

from model.core.features import Answer, PointsLike, SceneFeatures
from model.core.labelled import LabelledBoxes
from model.grounding.scene_encoder import SceneEncoder
from model.head.detector import HeadOutput
from model.nets.text import TextFeatures


class GroundingHead(nn.Module):
    """One grounding head (subclasses implement every method)."""

    takes_labelled_candidates: bool = False
    """Whether :meth:`encode` accepts labelled boxes as the only possible answers."""

    @property
    def min_score(self) -> float:
        """The smallest score :meth:`answer` returns when given no threshold."""
        raise NotImplementedError

    @property
    def uncalibrated_threshold(self) -> float:
        """The operating threshold of a checkpoint never calibrated (``model.training.calibrate``)."""
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
        score_threshold: float | None,
    ) -> Answer:
        """The boxes, scores and heatmaps of one encoded prompt on one encoded scene."""
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
