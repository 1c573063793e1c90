"""Starting a model of one class set from a checkpoint of another (``--init-other-classes CKPT``).

A checkpoint of the ``vod`` set (Car, Pedestrian, Cyclist) and a ``nuscenes`` model (ten classes)
share every weight but a few whose shape follows the class set (``--init`` refuses them,
:func:`model.training.start.check_class_set`). :func:`init_other_classes` copies every weight
whose name and shape match (the sensor branches, fusion, neck, the class-agnostic head branches,
the text path, the referent stage's blocks) and remaps the class-shaped ones by class *name*:

- the detector's heatmap output (``head.heatmap.1``: one output channel per class, axis 0): the
  rows of the classes both sets hold are copied (``vod`` -> ``nuscenes``: Car, Pedestrian); the
  other rows keep the new model's own initialisation (the heatmap's prior bias);
- the referent stage's geometry input (``referent.geometry.0.weight``, axis 1) and its text gate
  (``referent.geometry_gate``, axis 0): :func:`geometry_input_keys` names every column (a class's
  one-hot column, its context relation block, its picked-reference block, or a class-free
  feature); a column of the new layout whose name the checkpoint has is copied from it, the
  others start at zero (the layer computes for a candidate of a shared class what it did; a gate
  row at zero is ``2 sigmoid(0) = 1``, the ungated feature).

Any other shape mismatch is re-initialised whole. The result says which tensors were remapped or
re-initialised (:class:`ClassRemap`); the training run prints it and records it in the
checkpoint's metadata (``CheckpointMeta.class_remap``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch

from model.config import ModelConfig, ReferentConfig
from model.referent.candidates import class_columns, geometry_feature_width
from model.referent.compare import COMPARE_FEATURES
from model.referent.context import PER_CLASS, RANK_FEATURES
from model.referent.stage import geometry_input_width
from model.referent.subsets import PER_PICKED, PICKED, SUBSET_RANK_FEATURES
from model.tpcnet import head_class
from scenes.geometry.classes import ClassSet

ColumnKey = tuple[str, ...]
"""The name of one column (or channel): ``("class", name)``, ``("relation", name, i)``,
``("picked", name, i)`` or a class-free ``(block, i)``."""

HEATMAP_OUT = ("head.heatmap.1.weight", "head.heatmap.1.bias")
"""The detector head's class channels (axis 0)."""

GEOMETRY_IN = {
    "referent.geometry.0.weight": 1,
    "referent.geometry_gate.weight": 0,
    "referent.geometry_gate.bias": 0,
}
"""The referent stage's tensors indexed by the geometry input's columns, and along which axis."""


def geometry_input_keys(cfg: ReferentConfig, classes: ClassSet) -> list[ColumnKey]:
    """The name of each column of the referent stage's geometry input
    (:func:`model.referent.stage.geometry_input_width` columns, in the stage's order: the
    explicit geometry, the context features, the numeric comparisons, the subset features)."""
    names, count = classes.names, len(classes)
    width = geometry_feature_width(count)
    geometry: list[ColumnKey] = [("geometry", "")] * width
    for name, column in zip(names, class_columns(count), strict=True):
        geometry[int(column)] = ("class", name)
    free = [j for j, key in enumerate(geometry) if key[0] != "class"]
    for i, j in enumerate(free):
        geometry[j] = ("geometry", str(i))
    keys = geometry
    if cfg.context:
        keys += [("rank", str(i)) for i in range(RANK_FEATURES)]
        keys += [("relation", n, str(i)) for n in names for i in range(PER_CLASS)]
    subsets: list[ColumnKey] = []
    if cfg.subset_ranks:
        subsets += [("subset_rank", str(i)) for i in range(SUBSET_RANK_FEATURES)]
        per = len(PICKED) * PER_PICKED
        subsets += [("picked", n, str(i)) for n in names for i in range(per)]
    if cfg.numeric_compare:
        keys += [("compare", str(i)) for i in range(COMPARE_FEATURES)]
    keys += subsets
    if len(keys) != geometry_input_width(cfg, count):
        raise AssertionError("geometry_input_keys does not follow geometry_input_width")
    return keys


def remapped(
    own: torch.Tensor,
    given: torch.Tensor,
    axis: int,
    own_keys: list[ColumnKey],
    given_keys: list[ColumnKey],
    zero: bool,
) -> tuple[torch.Tensor, int]:
    """``own``'s shape filled along ``axis`` from ``given``'s entries of the same key; the others
    zero (``zero``) or ``own``'s. Returns the tensor and how many entries were not found."""
    out = torch.zeros_like(own) if zero else own.detach().clone()
    where = {key: i for i, key in enumerate(given_keys)}
    new = 0
    for j, key in enumerate(own_keys):
        i = where.get(key)
        if i is None:
            new += 1
        else:
            out.select(axis, j).copy_(given.select(axis, i))
    return out, new


@dataclass(frozen=True)
class ClassRemap:
    """What :func:`init_other_classes` did (stored in the checkpoint's metadata as a dict).

    Attributes:
        source: The checkpoint initialised from (as given).
        from_classes, to_classes: The class sets (its, the model's).
        shared: The classes of both sets, whose channels and columns were copied.
        copied: Tensors copied whole.
        remapped: Tensor name -> what was done (rows / columns copied by class, the rest new).
        reinitialised: Tensors left at the new model's initialisation (no counterpart).
    """

    source: str
    from_classes: str
    to_classes: str
    shared: tuple[str, ...]
    copied: int
    remapped: dict[str, str]
    reinitialised: tuple[str, ...]

    def to_dict(self) -> dict[str, object]:
        """The metadata's plain-JSON form."""
        out = asdict(self)
        out["shared"], out["reinitialised"] = list(self.shared), list(self.reinitialised)
        return out

    def lines(self) -> list[str]:
        """The report printed by the training run, one line each."""
        out = [
            f"initialised a {self.to_classes!r} model from {self.source} (class set "
            f"{self.from_classes!r}): {self.copied} weight tensors copied; classes of both: "
            f"{', '.join(self.shared) or 'none'}"
        ]
        out += [f"  remapped {name}: {what}" for name, what in self.remapped.items()]
        out += [f"  re-initialised {name}" for name in self.reinitialised]
        return out


def init_other_classes(model: torch.nn.Module, payload: dict, source: str) -> ClassRemap:
    """Initialise ``model`` (a :class:`model.tpcnet.TPCNet`) from a checked checkpoint payload
    of any class set (module docstring); returns what was done."""
    given_cfg = ModelConfig.from_dict(payload["config"])
    own_cfg: ModelConfig = model.cfg
    given_set, own_set = given_cfg.class_set, own_cfg.class_set
    shared = tuple(n for n in own_set.names if n in given_set)
    state, own = payload["state_dict"], model.state_dict()
    same: dict[str, torch.Tensor] = {}
    done: dict[str, str] = {}
    fresh: list[str] = []
    geometry_keys = None
    kinds = (head_class(own_cfg.grounding), head_class(given_cfg.grounding))
    if all(kind.takes_labelled_candidates for kind in kinds):  # both have a referent stage
        geometry_keys = (
            geometry_input_keys(own_cfg.referent, own_set),
            geometry_input_keys(given_cfg.referent, given_set),
        )
    for name, value in own.items():
        if name not in state:
            fresh.append(name)
            continue
        given = state[name]
        if given.shape == value.shape:
            same[name] = given
            continue
        keys = None
        if name in HEATMAP_OUT:
            axis, keys, zero, unit = 0, (list(own_set.names), list(given_set.names)), False, "rows"
        elif name in GEOMETRY_IN and geometry_keys is not None:
            axis, keys, zero = GEOMETRY_IN[name], geometry_keys, True
            unit = "columns" if axis == 1 else "rows"
        if keys is None or given.shape[axis] != len(keys[1]) or value.shape[axis] != len(keys[0]):
            fresh.append(name)
            continue
        others = [d for d in range(value.dim()) if d != axis]
        if any(value.shape[d] != given.shape[d] for d in others):
            fresh.append(name)
            continue
        same[name], new = remapped(value, given, axis, keys[0], keys[1], zero)
        start = "zero" if zero else "the new model's initialisation"
        done[name] = (
            f"{value.shape[axis] - new} of {value.shape[axis]} {unit} copied (class-free, or of a class of both sets), "
            f"{new} new ({start})"
        )
    model.load_state_dict(same, strict=False)
    copied = len(same) - len(done)
    return ClassRemap(source, given_set.name, own_set.name, shared, copied, done, tuple(fresh))


__all__ = ["ClassRemap", "geometry_input_keys", "init_other_classes", "remapped"]
