"""What a training root's labels hold for the model's class set, checked before the first step.

:func:`check_labels` refuses a root none of whose training frames has a label of the model's class
set (it would train to nothing and report mAP 0), and counts the labels it holds of classes outside
that set: what the readers leave out (:func:`scenes.frame.kitti.labels_to_boxes`; a ``Truck``
referent of a three-class root, the bicycles of a ``--classes nuscenes`` root for a three-class
model, VoD's riders and bicycle racks in ``--scene-labels``). ``python -m model.train`` says that
count once, on rank 0 (:func:`outside_line`), so that no label is dropped without a word.
"""

from __future__ import annotations

from pathlib import Path

from model.training.config import TrainingError
from model.training.data import RootSpec
from scenes.datasets.family_files import split_label_files
from scenes.frame.kitti import outside_class_counts, outside_class_phrase, read_label_file
from scenes.geometry.classes import VOD, ClassSet


def _add(total: dict[str, int], counts: dict[str, int]) -> None:
    for name, n in counts.items():
        total[name] = total.get(name, 0) + n


def check_labels(spec: RootSpec, split: str, classes: ClassSet = VOD) -> dict[str, int]:
    """Refuse a training root none of whose ``split`` frames has a label of ``classes`` (the
    model's class set; its ``label_2``, or its scene labels' where given); return the label names
    of the split's label files outside ``classes`` with their number of objects (each file read
    once; ``{}`` for a nuScenes root, whose annotations :class:`NuScenesFrames` reads).

    Raises:
        TrainingError: an empty split, or no label of ``classes`` in it.
    """
    if spec.talk2car is not None:
        return {}  # a nuScenes root: NuScenesFrames refuses a split without a referred command
    split_labels = split_label_files(spec.path, split, spec.scene_labels)
    ids = split_labels.ids
    if not ids:
        raise TrainingError(f"{split_labels.split_list}: split {split!r} is empty")
    found, outside, seen = False, {}, set()
    for path in split_labels.files:
        if path in seen or not path.is_file():
            continue
        seen.add(path)
        labels = read_label_file(path)
        found = found or any(classes.label_index(x.name) >= 0 for x in labels)
        _add(outside, outside_class_counts(labels, classes))
    if not found:
        raise TrainingError(
            f"{split_labels.folder}: no label of the {len(ids)} samples of split {split!r} has a "
            f"{', '.join(classes.names)} box ({classes.name!r} class set): nothing to train on"
        )
    return dict(sorted(outside.items()))


def outside_line(spec: RootSpec, split: str, counts: dict[str, int], classes: ClassSet) -> str:
    """The one line training says about :func:`check_labels`' count of a root (``""`` for none):
    ``"note: ROOT split 'train': 4 labels of classes outside the model's set (Truck 3, Tram 1)
    are left out of training (the model's 'vod' set: Car, Pedestrian, Cyclist)"``."""
    if not counts:
        return ""
    where = Path(spec.scene_labels) if spec.scene_labels is not None else Path(spec.path)
    return (
        f"note: {where} split {split!r}: {outside_class_phrase(counts, 'labels')} are left out "
        f"of training (the model's {classes.name!r} set: {', '.join(classes.names)})"
    )
