"""What other packages may rely on of a grounding model: the typed protocol that
:class:`model.tpcnet.TPCNet` satisfies and that the app, the class-prompt scorer and the
evaluation commands are written against (a fake with these members works in their tests).

No torch here: ``from model import GroundingModel`` stays cheap for the app.
"""

from __future__ import annotations

from typing import Protocol, TypeVar, runtime_checkable

import numpy as np

from scenes.geometry.classes import VOD, ClassSet


class GridExtent(Protocol):
    """The BEV extent of a heatmap grid (:class:`model.core.grid.BevGrid` has it), metres,
    LiDAR frame."""

    @property
    def x_min(self) -> float: ...

    @property
    def x_max(self) -> float: ...

    @property
    def y_min(self) -> float: ...

    @property
    def y_max(self) -> float: ...


@runtime_checkable
class PredictionsView(Protocol):
    """What is read of one answer (:class:`model.core.features.Predictions` satisfies it)."""

    @property
    def boxes(self) -> np.ndarray:
        """``(K, 7)`` ``x, y, z, l, w, h, yaw``, LiDAR frame, best score first."""
        ...

    @property
    def scores(self) -> np.ndarray:
        """``(K,)`` in ``[0, 1]``."""
        ...

    @property
    def classes(self) -> tuple[str, ...]:
        """``K`` class names of the model's class set (``ModelConfig.class_set``)."""
        ...

    @property
    def heatmaps(self) -> np.ndarray:
        """``(3, H, W)`` sigmoid heatmaps on :attr:`grid`, ``heatmaps[c, iy, ix]``."""
        ...

    @property
    def grid(self) -> GridExtent: ...


class ModelSettings(Protocol):
    """What is read of a model's configuration (:class:`model.config.ModelConfig`)."""

    @property
    def modalities(self) -> str:
        """``"both"``, ``"lidar"`` or ``"radar"``: the sensors the model was built for."""
        ...

    @property
    def class_set(self) -> ClassSet:
        """The classes the model detects and names (:func:`model_classes` reads it)."""
        ...


Features = TypeVar("Features")
"""A model's encoded scene (:class:`model.core.features.SceneFeatures`); callers only keep it."""


@runtime_checkable
class GroundingModel(Protocol[Features]):
    """A grounding model (:class:`model.tpcnet.TPCNet` satisfies it): ``encode_scene`` once per
    scene, ``ground`` once per prompt.

    A model without ``cfg`` (or with None) counts as a two-sensor model of the ``vod`` class set
    (:func:`model_classes`) with no threshold of its own (the app's :func:`app.engine.initial_threshold` and ``model_modalities`` read it). A
    model may also say ``takes_labelled_candidates`` (``encode_scene(..., candidates=...)``: the
    frame's labelled boxes as the only possible answers); one that does not, does not take them.
    """

    @property
    def cfg(self) -> ModelSettings | None: ...

    def encode_scene(self, lidar: np.ndarray | None, radar: np.ndarray | None) -> Features: ...

    def ground(
        self, features: Features, prompt: str, score_threshold: float | None = None
    ) -> PredictionsView: ...


def model_classes(model: object) -> ClassSet:
    """The class set a model detects and names (``model.cfg.class_set``,
    :mod:`scenes.geometry.classes`); ``vod`` for a model without a config or without one there
    (a test's fake)."""
    found = getattr(getattr(model, "cfg", None), "class_set", None)
    return found if isinstance(found, ClassSet) else VOD
