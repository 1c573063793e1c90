"""The model a training run starts from: a resumed run's, or a new one built from the run's
settings and initialised from another checkpoint as asked (``--init``: every weight whose name and
shape match, a grown input widened; ``--init-detector``: the scene encoder and detector only,
over ``--init``'s when both are given, a retrained detector under an earlier referent stage;
``--init-other-classes``: a checkpoint of another class set, :mod:`model.training.class_remap`).

A new model carries the class remapping of its start in ``model.checkpoint_metadata.class_remap``
(its own ``--init-other-classes``, or the one its ``--init`` checkpoint records: the lineage), and
the run writes it into every checkpoint (:func:`model.training.loop.set_up`).
"""

from __future__ import annotations

import sys
from dataclasses import asdict, replace
from pathlib import Path

import torch

from model.checkpoint import model_from_payload, read_checkpoint
from model.checkpoint_meta import CheckpointMeta
from model.tpcnet import TPCNet, build_model
from model.training.config import TrainConfig, TrainingError
from model.training.state import (
    LAST_FILE,
    RunState,
    TrainState,
    check_resumable,
    load_run,
    state_path,
    trim_log,
)

SCENE_MODULES = ("lidar.", "radar.", "fusion.", "neck.", "head.")
"""Parameter-name prefixes of the scene encoder and detector (what ``--init-detector`` copies)."""


def widened(own: torch.Tensor, given: torch.Tensor, axis: int = 1) -> torch.Tensor | None:
    """``given`` as a tensor of ``own``'s shape that is larger along ``axis`` only: ``given``
    first along that axis, the new entries zero; or None when the shapes are not so related.
    For a linear weight ``(O, I)`` whose input grew (``axis=1``) the layer computes what it did
    before; for a gate whose outputs grew (``axis=0``, weight and bias) the new outputs are
    ``2 sigmoid(0) = 1``."""
    if own.dim() != given.dim() or not 0 <= axis < own.dim():
        return None
    others = [d for d in range(own.dim()) if d != axis]
    if any(own.shape[d] != given.shape[d] for d in others) or own.shape[axis] <= given.shape[axis]:
        return None
    out = torch.zeros_like(own)
    out.narrow(axis, 0, given.shape[axis]).copy_(given)
    return out


WIDENABLE = {
    "referent.geometry.0.weight": 1,
    "referent.geometry_gate.weight": 0,
    "referent.geometry_gate.bias": 0,
}
"""Checkpoint names of the weights that may have grown since, and along which axis: the referent
stage's geometry input (wider with ``ReferentConfig.context`` and ``numeric_compare``) and its
text gate's outputs (as many as those inputs); any other shape mismatch is not copied."""


def check_class_set(payload: dict, path: str, wanted: str) -> None:
    """Refuse a checkpoint (a checked payload) of another class set than ``wanted``: its heatmap,
    class evidence and per-class context have other channels, and copying the rest would
    mislabel every class. One line, naming the file."""
    head = payload["config"].get("head") if isinstance(payload["config"], dict) else None
    stored = head.get("classes", "vod") if isinstance(head, dict) else "vod"
    if stored != wanted:
        raise TrainingError(
            f"{path}: a checkpoint of the {stored!r} class set cannot start a {wanted!r} model "
            f"(--classes {wanted}); give a {wanted!r} checkpoint, train from scratch, or start "
            f"from it with --init-other-classes {path}"
        )


def init_from(model: torch.nn.Module, path: str, prefixes: tuple[str, ...] = ()) -> int:
    """Copy every weight of the checkpoint at ``path`` whose name and shape match ``model``'s
    (e.g. the sensor branches, fusion, neck and head of a paper-path checkpoint into a referent
    model), only names starting with one of ``prefixes`` when given; a weight of
    :data:`WIDENABLE` that grew (the referent stage's geometry input with
    ``ReferentConfig.context`` or ``numeric_compare`` switched on, and its text gate) is copied
    into its first entries, the new ones zero (:func:`widened`). Returns how many tensors were
    copied. A checkpoint of another class set is refused (:func:`check_class_set`)."""
    payload = read_checkpoint(path)
    check_class_set(payload, path, model.cfg.class_set.name)
    state = payload["state_dict"]
    own = model.state_dict()
    same = {}
    for k, v in state.items():
        if k not in own or (prefixes and not k.startswith(prefixes)):
            continue
        if own[k].shape == v.shape:
            same[k] = v
        elif k in WIDENABLE and (grown := widened(own[k], v, WIDENABLE[k])) is not None:
            same[k] = grown
    if not same:
        raise TrainingError(f"{path}: no weight matches this model's names and shapes")
    model.load_state_dict(same, strict=False)
    return len(same)


def start_overrides(cfg: TrainConfig) -> dict[str, object]:
    """``cfg``'s model overrides, plus the start checkpoint's ground (``PillarConfig.ground`` and
    ``ground_height``: how its detector sees heights) when ``--ground`` is not given and the model
    starts from a checkpoint of its own grounding kind (``--init-detector``, else ``--init`` or
    ``--init-other-classes``)."""
    out = cfg.model_overrides()
    start = cfg.init_detector or cfg.init or cfg.init_other_classes
    if cfg.ground is None and start:
        config = read_checkpoint(start)["config"]
        if config.get("grounding") != cfg.grounding:
            return out
        pillars = config.get("pillars", {})
        out["pillars__ground"] = pillars.get("ground", "sensor")
        if "ground_height" in pillars:
            out["pillars__ground_height"] = pillars["ground_height"]
    return out


def start_model(
    cfg: TrainConfig, resume: bool, rank: int, world: int, device: torch.device
) -> tuple[TPCNet, RunState | None, TrainState]:
    """The run's model (resumed, or built and initialised as asked), its saved run state (None
    for a new run) and the progress to start from."""
    out = Path(cfg.out)
    if resume and (state_path(out).is_file() or (out / LAST_FILE).is_file()):
        run = load_run(out, repair=rank == 0)
        check_resumable(asdict(cfg), run, world)
        model = model_from_payload(run.model, state_path(out), device)
        state = replace(run.progress)
        if rank == 0:
            trim_log(out, state.step)
        if not run.rng and rank == 0:
            print(
                f"{state_path(out)}: a run state of the older layout, without RNG states: the "
                "resumed run will not repeat an uninterrupted one bit for bit",
                file=sys.stderr,
            )
        return model, run, state
    if resume:
        print(f"{out}: nothing to resume, starting a new run", file=sys.stderr)
    model = build_model(cfg.preset, **start_overrides(cfg))
    remap = None
    if cfg.init:
        copied = init_from(model, cfg.init)
        print(f"initialised {copied} weight tensors from {cfg.init}", file=sys.stderr)
        remap = CheckpointMeta.from_dict(read_checkpoint(cfg.init)["metadata"]).class_remap
    if cfg.init_other_classes:
        from model.training.class_remap import init_other_classes

        done = init_other_classes(
            model, read_checkpoint(cfg.init_other_classes), cfg.init_other_classes
        )
        if rank == 0:
            print("\n".join(done.lines()), file=sys.stderr)
        remap = done.to_dict()
    if cfg.init_detector:
        copied = init_from(model, cfg.init_detector, SCENE_MODULES)
        rest = f"the rest from {cfg.init}" if cfg.init else "the referent stage starts from scratch"
        print(
            f"initialised the scene encoder and detector ({copied} tensors) from "
            f"{cfg.init_detector}; {rest}",
            file=sys.stderr,
        )
    model.checkpoint_metadata = CheckpointMeta(class_remap=remap)
    return model, None, TrainState()
