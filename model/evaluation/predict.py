"""Run a model over a split of a Talk2Radar root and write KITTI prediction files.

The writer follows mmdet3d's ``KittiMetric`` as the Talk2Radar workflow uses it (spec §1.7, §2.2):

- one ``<frame id>.txt`` per frame of the split, **empty when nothing is found** (the VoD
  evaluator takes its frame list from the prediction folder, so a missing file would silently drop
  that frame's ground truth);
- each line ``Class -1 -1 alpha x1 y1 x2 y2 h w l x y z ry score`` with four decimals, the camera-
  frame bottom centre, and the *real* projected and clipped 2D box (the evaluator ignores
  detections whose 2D height is under 40 px);
- a detection is kept only if its 2D box overlaps the image and its LiDAR-frame bottom centre lies
  strictly inside ``pcd_limit_range = [0, -40, -3, 70.4, 40, 0]``.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import numpy as np
import torch
from tqdm import tqdm

from model.checkpoint_meta import CheckpointMeta
from model.core.labelled import LabelledBoxes
from model.evaluation.grounding import PromptBoxes
from scenes.frame import FrameSource, Sample
from scenes.frame.kitti import ObjectLabel, boxes_to_labels, write_label_file
from scenes.geometry.calib import IMAGE_SIZE, Calibration, bottom_centres
from scenes.utils.lru import LRUCache

if TYPE_CHECKING:
    from model.core.features import Predictions, SceneFeatures
    from model.tpcnet import TPCNet

T = TypeVar("T")

PCD_LIMIT_RANGE = (0.0, -40.0, -3.0, 70.4, 40.0, 0.0)
"""mmdet3d's default ``pcd_limit_range`` (x_min, y_min, z_min, x_max, y_max, z_max), LiDAR frame."""


def prediction_labels(
    boxes: np.ndarray,
    classes: Sequence[str],
    scores: np.ndarray,
    calib: Calibration,
    image_size: tuple[int, int] = IMAGE_SIZE,
) -> list[ObjectLabel]:
    """Turn LiDAR-frame detections into KITTI prediction labels, filtered as ``KittiMetric`` does.

    Args:
        boxes: ``(K, 7)`` LiDAR frame, z at the geometric centre.
        classes: ``K`` class names.
        scores: ``(K,)`` confidences.
        calib: The frame's LiDAR calibration.

    Returns:
        The kept detections as labels (``truncated = occluded = -1``), in input order.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(b) == 0:
        return []
    labels = boxes_to_labels(
        b,
        list(classes),
        calib,
        scores=np.asarray(scores),
        image_size=image_size,
        truncated=-1.0,
        occluded=-1,
    )
    width, height = image_size
    lo, hi = np.array(PCD_LIMIT_RANGE[:3]), np.array(PCD_LIMIT_RANGE[3:])
    kept = []
    for label, centre in zip(labels, bottom_centres(b), strict=True):
        x1, y1, x2, y2 = label.bbox
        in_image = x1 < width and y1 < height and x2 > 0 and y2 > 0
        in_range = bool(np.all(centre > lo) and np.all(centre < hi))
        if in_image and in_range:
            kept.append(label)
    return kept


def operating_threshold(model: TPCNet) -> float:
    """The score above which the model's boxes are its answer (the set metrics, the app).

    ``model.checkpoint_metadata["operating_threshold"]`` where the checkpoint stores one (set by
    ``python -m model.calibrate``); else its grounding head's ``uncalibrated_threshold`` (the
    referent head's ``model.grounding.referent.UNCALIBRATED_REFERENT``, a referent probability: the
    decision boundary its BCE training draws; the paper's head's decoder threshold
    ``model.cfg.head.score_threshold``).

    Raises:
        ValueError: the stored value is not a number in ``[0, 1)`` (the message names the field).
    """
    value = CheckpointMeta.of(model).operating_threshold
    if value is None:
        return float(model.grounding.uncalibrated_threshold)
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0.0 <= value < 1.0:
        raise ValueError(
            f"checkpoint metadata field 'operating_threshold' must be a number in [0, 1), "
            f"got {value!r}"
        )
    return float(value)


def decode_threshold(model: TPCNet) -> float:
    """The smallest score ``model.ground`` returns when given no threshold: its grounding
    head's ``min_score`` (the referent stage's ``cfg.referent.min_score``, the paper's decoder's
    ``cfg.head.score_threshold``)."""
    return float(model.grounding.min_score)


SceneKey = tuple[object, ...]
"""Identity of a sample's sensor data (see :func:`scene_key`)."""


def scene_key(root: FrameSource, sample_id: str) -> SceneKey:
    """The identity of a sample's frame: :meth:`scenes.frame.FrameSource.frame_key`."""
    return root.frame_key(sample_id)


@dataclass(frozen=True)
class FramePrediction:
    """The model's answer for one sample, with its ground truth and timing.

    Attributes:
        sample: The sample (from a worker process, :mod:`model.evaluation.predict_pool`, with
            empty ``lidar`` and ``radar``: the points stay in the worker).
        boxes: ``(K, 7)`` LiDAR frame, sorted by score (every box the grounding threshold kept).
        scores: ``(K,)``.
        classes: ``K`` class names.
        labels: KITTI prediction labels of the boxes scoring at least ``min_label_score`` (see
            :func:`iterate_predictions`), filtered as :func:`prediction_labels`.
        seconds: ``encode_scene`` (of this sample's scene, measured once when shared) + ``ground``.
        features: The encoded scene (to ground other prompts on it); None from a worker.
        scene_key: :func:`scene_key` of the sample.
        extra: Each of :attr:`PredictSettings.extra_prompts`'s prompts for this sample -> its
            answer on the same scene (e.g. the class-noun baseline).
    """

    sample: Sample
    boxes: np.ndarray
    scores: np.ndarray
    classes: tuple[str, ...]
    labels: list[ObjectLabel]
    seconds: float
    features: SceneFeatures | None = field(default=None, repr=False, compare=False)
    scene_key: SceneKey = ()
    extra: Mapping[str, PromptBoxes] = field(default_factory=dict, repr=False)


@dataclass(frozen=True)
class PredictSettings:
    """How each sample is predicted (:class:`FramePredictor`); picklable where workers are used
    (the callables then module-level functions or instances of module-level classes).

    Attributes:
        score_threshold: Decoding threshold given to ``ground`` (None: the model's own).
        min_label_score: Only boxes scoring at least this become :attr:`FramePrediction.labels`.
        cache_scenes: Encoded scenes kept (most recently used first) for the following samples
            with the same :func:`scene_key`; ids in world order (as ``scenes.synth`` writes them)
            encode each world once. 0 encodes every sample.
        candidates: Referent path: the labelled boxes of a sample's frame, among which the
            referent stage then chooses (``model.evaluate --candidates labels``); None: the
            detector's proposals.
        extra_prompts: Further prompts to ground on each sample's scene (answered once per scene
            and prompt, :attr:`FramePrediction.extra`); None: none.
    """

    score_threshold: float | None = None
    min_label_score: float = 0.0
    cache_scenes: int = 4
    candidates: Callable[[Sample], LabelledBoxes] | None = None
    extra_prompts: Callable[[Sample], Sequence[str]] | None = None


@dataclass(frozen=True)
class FrameInput:
    """A sample as read for prediction (:meth:`FramePredictor.read`)."""

    sample: Sample
    key: SceneKey
    labelled: LabelledBoxes | None


@dataclass
class _Scene:
    """An encoded scene in the cache: its features, encoding time and extra prompts' answers."""

    features: SceneFeatures
    seconds: float
    answers: dict[str, PromptBoxes] = field(default_factory=dict)


def _boxes(pred: Predictions, source: str) -> PromptBoxes:
    """The boxes, classes and scores of ``model.ground``'s answer (float64), checked."""
    return PromptBoxes.make(pred.boxes, pred.classes, pred.scores, source=source)


class FramePredictor:
    """The per-sample work of a prediction run, one home for it whether it runs in this process
    (:func:`iterate_predictions`) or in worker processes (:mod:`model.evaluation.predict_pool`):
    read a sample, encode its scene once (an LRU cache of :attr:`PredictSettings.cache_scenes`
    scenes), ground its prompt and the extra prompts, turn the answer into labels."""

    def __init__(self, model: TPCNet, root: FrameSource, settings: PredictSettings) -> None:
        self.model = model
        self.root = root
        self.settings = settings
        model.eval()
        warm_up = getattr(getattr(model, "text_encoder", None), "warm_up", None)
        if warm_up is not None:
            warm_up()  # the text encoder loads while the first scenes are read and encoded
        self._cache: LRUCache[SceneKey, _Scene] = LRUCache(max(settings.cache_scenes, 0))

    def read(self, sid: str) -> FrameInput:
        """Read sample ``sid`` (and its candidates); errors name the file."""
        sample = self.root.load(sid)
        if sample.prompt is None:
            raise ValueError(f"{self.root.path}: sample {sid} has no prompt to ground")
        candidates = self.settings.candidates
        labelled = None if candidates is None else candidates(sample)
        return FrameInput(sample, scene_key(self.root, sid), labelled)

    def predict(self, item: FrameInput) -> FramePrediction:
        """Encode (unless cached) and ground one read sample (no gradients)."""
        model, settings, sample = self.model, self.settings, item.sample
        with torch.no_grad():
            scene = self._cache.get(item.key)
            if scene is None:
                start = time.perf_counter()
                if item.labelled is None:
                    features = model.encode_scene(sample.lidar, sample.radar)
                else:
                    features = model.encode_scene(
                        sample.lidar, sample.radar, candidates=item.labelled
                    )
                scene = _Scene(features, time.perf_counter() - start)
                self._cache.put(item.key, scene)
            start = time.perf_counter()
            pred = model.ground(
                scene.features, sample.prompt, score_threshold=settings.score_threshold
            )
            seconds = scene.seconds + time.perf_counter() - start
            extra = {}
            for prompt in () if settings.extra_prompts is None else settings.extra_prompts(sample):
                if prompt not in scene.answers:
                    extra_pred = model.ground(
                        scene.features, prompt, score_threshold=settings.score_threshold
                    )
                    where = f"{self.root.path}: sample {sample.sample_id}, prompt {prompt!r}"
                    scene.answers[prompt] = _boxes(extra_pred, where)
                extra[prompt] = scene.answers[prompt]
        answer = _boxes(pred, f"{self.root.path}: sample {sample.sample_id}")
        keep = answer.scores >= settings.min_label_score
        labels = prediction_labels(
            answer.boxes[keep],
            [c for c, k in zip(answer.classes, keep, strict=True) if k],
            answer.scores[keep],
            sample.calib,
        )
        return FramePrediction(
            sample,
            answer.boxes,
            answer.scores,
            answer.classes,
            labels,
            seconds,
            scene.features,
            item.key,
            extra,
        )


def iterate_predictions(
    model: TPCNet,
    root: FrameSource,
    ids: Sequence[str],
    score_threshold: float | None = None,
    progress: bool = True,
    min_label_score: float = 0.0,
    cache_scenes: int = 4,
    candidates: Callable[[Sample], LabelledBoxes] | None = None,
    extra_prompts: Callable[[Sample], Sequence[str]] | None = None,
) -> Iterator[FramePrediction]:
    """Run ``model.encode_scene`` + ``model.ground`` on each sample in this process (eval mode,
    no gradients; :class:`FramePredictor`, the arguments as :class:`PredictSettings`'s fields),
    the next samples read ahead by a thread (:func:`read_ahead`)."""
    settings = PredictSettings(
        score_threshold, min_label_score, cache_scenes, candidates, extra_prompts
    )
    predictor = FramePredictor(model, root, settings)
    bar = tqdm(total=len(ids), desc="predict", unit="frame", disable=not progress)
    with bar:
        for item in read_ahead(predictor.read, ids):
            bar.update(1)
            yield predictor.predict(item)


def read_ahead(read: Callable[[str], T], ids: Sequence[str], ahead: int = 2) -> Iterator[T]:
    """``read(id)`` of each id, in order, computed up to ``ahead`` ids in advance by one worker
    thread (file reading and parsing overlap the model's work, which releases the GIL). An error
    of ``read`` is raised where its id's result is taken, as if read there."""
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="read-ahead") as pool:
        pending: deque[Future[T]] = deque()
        todo = iter(ids)
        try:
            for sid in islice(todo, ahead):
                pending.append(pool.submit(read, sid))
            while pending:
                done = pending.popleft()
                nxt = next(todo, None)
                if nxt is not None:
                    pending.append(pool.submit(read, nxt))
                yield done.result()
        finally:
            for future in pending:
                future.cancel()


def write_predictions(predictions: dict[str, list[ObjectLabel]], out_dir: str | Path) -> Path:
    """Write one prediction file per frame (empty files included) into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for sid, labels in predictions.items():
        write_label_file(out / f"{sid}.txt", labels, decimals=4)
    return out
