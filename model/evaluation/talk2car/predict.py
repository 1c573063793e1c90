"""Ground a split's Talk2Car commands with a model, and the release-format predictions file.

Each nuScenes sample a command refers to is read once (``NuScenesRoot.frame``) and encoded once
(``model.encode_scene``); each of its commands is then answered on it (``model.ground``), and the
class-noun prompt of the referent's class beside it (the class-noun baseline,
:func:`model.evaluation.baselines.class_noun_prompt`). Boxes are in the model frame; the predictions
file (:func:`predictions_json`) turns them into the command file's CAM_FRONT camera frame with
``scenes.nuscenes.talk2car.model_box_to_camera`` (the conversion's one home) and adds each box's
2D box projected into CAM_FRONT (:func:`projected_2d_box`, Talk2Car's ``[x, y, w, h]``).

A Talk2Car command refers to exactly one object, so its answer is never empty: the candidates
scoring at least the smallest score kept (the referent stage's ``min_score``), or else the
best-ranked one alone, however unsure the stage is (``min_score`` and the operating threshold are
for the answer *set* of a Talk2Radar prompt, which may be empty). With ``min_score`` alone, 11 to
14 of 211 val commands got no box, top-1 misses whatever their ranking; keeping every candidate
instead made the evaluation five times slower (docs/RESULTS_HISTORY.md, "Talk2Car on synthetic nuScenes
roots").
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, fields, is_dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from tqdm import tqdm

from model.evaluation.baselines import class_noun_prompt
from model.evaluation.talk2car.metrics import CommandBoxes
from scenes.geometry.calib import boxes_2d, boxes_lidar_to_camera
from scenes.geometry.projection import in_camera_view

if TYPE_CHECKING:
    from model.tpcnet import TPCNet

ToCamera = Callable[[Any, np.ndarray], tuple[Sequence[float], Sequence[float], Sequence[float]]]
"""``(NuScenesFrame, box (7,)) -> (translation (3,), size_wlh (3,), rotation_wxyz (4,))``."""


@dataclass(frozen=True)
class CommandPrediction:
    """The model's answer to one command, with what the metrics need.

    Attributes:
        command: The ``Talk2CarCommand``.
        frame: Its sample's ``NuScenesFrame`` (calibration, image size, description); its point
            clouds are dropped once encoded (empty arrays).
        answer: The boxes (model frame, best first) and the referent.
        noun: The class-noun prompt's answer on the same scene.
        in_view_same_class: Annotations of the referent's class whose box the front camera sees
            (the language-blind baseline chooses among them).
        referent_in_view: Whether the referent is one of them.
    """

    command: Any
    frame: Any
    answer: CommandBoxes
    noun: CommandBoxes
    in_view_same_class: int
    referent_in_view: bool

    @property
    def description(self) -> str:
        """The scene's description (rain and night subsets)."""
        return str(getattr(self.frame, "description", ""))


def projected_2d_box(box: np.ndarray, frame: Any) -> list[float] | None:
    """A model-frame box ``(7,)`` projected into the frame's CAM_FRONT image and clipped to it:
    ``[x, y, w, h]`` pixels (Talk2Car's ``2d_box``), or None when the camera does not see it."""
    b = np.asarray(box, dtype=np.float64).reshape(1, 7)
    if not in_camera_view(b, frame.calib, frame.image_size)[0]:
        return None
    x1, y1, x2, y2 = boxes_2d(boxes_lidar_to_camera(b, frame.calib), frame.calib, frame.image_size)[
        0
    ]
    return [float(x1), float(y1), float(x2 - x1), float(y2 - y1)]


def without_points(frame: Any) -> Any:
    """The frame with its point clouds (and their times) dropped: what a prediction keeps."""
    if not is_dataclass(frame):
        return frame
    names = {f.name for f in fields(frame)}
    empty = {"lidar": (0, 4), "radar": (0, 7), "lidar_time": (0,), "radar_time": (0,)}
    return replace(
        frame, **{k: np.zeros(shape, np.float32) for k, shape in empty.items() if k in names}
    )


def _boxes(pred: Any, referent: np.ndarray, cls: str, floor: float) -> CommandBoxes:
    """The answer's boxes best first: those scoring at least ``floor``, or the best one alone
    (module docstring)."""
    boxes = np.asarray(pred.boxes, dtype=np.float64).reshape(-1, 7)
    scores = np.asarray(pred.scores, dtype=np.float64).reshape(-1)
    order = np.argsort(-scores, kind="stable")
    order = order[: max(int((scores >= floor).sum()), min(1, len(order)))]
    classes = [tuple(pred.classes)[i] for i in order]
    return CommandBoxes.make(boxes[order], scores[order], referent, cls, classes)


def iterate_command_predictions(
    model: TPCNet,
    root: Any,
    commands: Any,
    model_class: Callable[[str, Sequence[str]], str | None],
    score_threshold: float | None = None,
    progress: bool = True,
    limit: int = 0,
) -> Iterator[CommandPrediction]:
    """Answer every kept command of ``commands`` (a ``CommandSet`` of ``root``) that has a referent,
    sample by sample in the root's order (each scene encoded once; eval mode, no gradients);
    ``score_threshold``: the smallest score kept (None: the model's ``min_score``), the best
    candidate kept whatever its score (module docstring); ``limit``: the first N samples
    only (0: all)."""
    by_sample: dict[str, list[Any]] = {}
    for command in commands.commands:
        if command.command_token in commands.referent:
            by_sample.setdefault(command.sample_token, []).append(command)
    order = {token: i for i, token in enumerate(root.samples)}
    tokens = sorted(by_sample, key=lambda t: order.get(t, len(order)))
    if limit:
        tokens = tokens[:limit]
    model.eval()
    floor = float(model.grounding.min_score if score_threshold is None else score_threshold)
    for token in tqdm(tokens, desc="predict", unit="sample", disable=not progress):
        frame = root.frame(token)
        boxes = np.asarray(frame.boxes, dtype=np.float64).reshape(-1, 7)
        classes = [
            model_class(c, a) for c, a in zip(frame.categories, frame.attributes, strict=True)
        ]
        seen = in_camera_view(boxes, frame.calib, frame.image_size)
        with torch.no_grad():
            features = model.encode_scene(frame.lidar, frame.radar)
            kept = without_points(frame)
            nouns: dict[str, Any] = {}
            for command in by_sample[token]:
                found = commands.referent[command.command_token]
                referent, cls, index = found.box, found.cls, found.index
                pred = model.ground(features, command.text, score_threshold=0.0)
                if cls not in nouns:
                    nouns[cls] = model.ground(features, class_noun_prompt(cls), score_threshold=0.0)
                same = [i for i, c in enumerate(classes) if c == cls and seen[i]]
                yield CommandPrediction(
                    command,
                    kept,
                    _boxes(pred, referent, cls, floor),
                    _boxes(nouns[cls], referent, cls, floor),
                    len(same),
                    int(index) in same,
                )


def prediction_entries(prediction: CommandPrediction, to_camera: ToCamera) -> list[dict[str, Any]]:
    """One command's entries of the predictions file, best first: ``translation`` (3), ``size``
    (w, l, h), ``rotation`` (w, x, y, z) in the command file's CAM_FRONT frame, ``score``,
    ``2d_box`` (``[x, y, w, h]`` or None where the camera does not see the box)."""
    out = []
    for box, score in zip(prediction.answer.boxes, prediction.answer.scores, strict=True):
        translation, size, rotation = to_camera(prediction.frame, box)
        out.append(
            {
                "translation": [round(float(v), 4) for v in translation],
                "size": [round(float(v), 4) for v in size],
                "rotation": [round(float(v), 6) for v in rotation],
                "score": round(float(score), 6),
                "2d_box": projected_2d_box(box, prediction.frame),
            }
        )
    return out


def predictions_json(
    predictions: Sequence[CommandPrediction], to_camera: ToCamera
) -> dict[str, list[dict[str, Any]]]:
    """``{command_token: entries}`` (:func:`prediction_entries`) of every prediction."""
    return {p.command.command_token: prediction_entries(p, to_camera) for p in predictions}


__all__ = [
    "CommandPrediction",
    "ToCamera",
    "iterate_command_predictions",
    "prediction_entries",
    "predictions_json",
    "projected_2d_box",
]
