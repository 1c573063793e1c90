"""An adaptation run's files: the resumable state ``RUN/adapt_state.pt`` and the checkpoints.

The state (one :func:`scenes.utils.durable.atomic_file` write, plain data and tensors, read with
``torch.load(weights_only=True)``) holds the run's settings (:meth:`AdaptConfig.settings`), the
model (:func:`model.checkpoint.checkpoint_payload`), the optimiser, :class:`Progress` (the round,
the step in it, the round whose pseudo-labels the memory holds), every frame's pseudo-label memory
(:class:`model.adapt.pseudo.FrameMemory`), the report so far, the metadata of the initial
checkpoint and the global RNG states (:func:`model.training.state.rng_state`). It is written once
the round's pseudo-labels are made, at the end of each round and when a signal stops the run, so
a run given the same ``--out`` again repeats what an uninterrupted one does: data order and
augmentations are drawn from ``(seed, round, step, item)``.

Checkpoints (:func:`adapted_meta`): ``RUN/last.pt`` and ``RUN/round<k>.pt`` (after round ``k``)
are ordinary model checkpoints whose metadata is the initial checkpoint's (its training settings
and data, its operating threshold: the referent stage is unchanged) with the lineage added: an
``adaptation`` entry (the initial checkpoint, the data root, the rounds done, the settings) and a
line appended to ``training_stages``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from model.adapt.config import AdaptConfig, AdaptError
from model.adapt.pseudo import FrameMemory
from model.checkpoint import CheckpointError, check_payload, checkpoint_payload
from model.checkpoint_meta import CheckpointMeta, portable_path
from model.tpcnet import TPCNet
from model.training.state import same_folder
from scenes.utils.durable import atomic_file

STATE_FILE = "adapt_state.pt"
REPORT_FILE = "adapt_report.json"
LAST_FILE = "last.pt"
FORMAT = "talk2pc-adapt-state"
FORMAT_VERSION = 1


def round_file(rounds_done: int) -> str:
    """The checkpoint after ``rounds_done`` rounds (``round1.pt``, ...)."""
    return f"round{rounds_done}.pt"


@dataclass
class Progress:
    """Where a run stands.

    Attributes:
        round: Rounds finished.
        step_in_round: Steps done in the round under way.
        labelled_round: The round whose pseudo-labels the memory holds (-1: none yet).
    """

    round: int = 0
    step_in_round: int = 0
    labelled_round: int = -1


@dataclass
class RunFiles:
    """A run's resumable state (module docstring)."""

    model: dict[str, Any]
    optimizer: dict[str, Any]
    progress: Progress
    memory: dict[str, FrameMemory]
    report: list[dict[str, Any]]
    init_meta: dict[str, Any]
    rng: dict[str, Any] | None


def state_path(out: str | Path) -> Path:
    return Path(out) / STATE_FILE


def save_state(out: Path, cfg: AdaptConfig, files: RunFiles) -> None:
    """Write the state atomically."""
    memory = {
        sid: {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in m.to_arrays().items()}
        for sid, m in files.memory.items()
    }
    payload = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "settings": cfg.settings(),
        "model": files.model,
        "optimizer": files.optimizer,
        "progress": asdict(files.progress),
        "memory": memory,
        "report": files.report,
        "init_meta": files.init_meta,
        "rng": files.rng,
    }
    out.mkdir(parents=True, exist_ok=True)
    with atomic_file(state_path(out)) as fh:
        torch.save(payload, fh)


def load_state(out: Path, cfg: AdaptConfig) -> RunFiles | None:
    """The saved state of ``out`` (None: no state there). Refuses, in one line naming the file,
    a state of another format or of other settings (but ``--stop-after-round`` and ``--quiet``).
    """
    path = state_path(out)
    if not path.is_file():
        return None
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise AdaptError(f"{path}: corrupt or not a torch file: {first}") from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise AdaptError(f"{path}: not a {FORMAT} file")
    if data.get("format_version") != FORMAT_VERSION:
        raise AdaptError(f"{path}: format_version {data.get('format_version')!r}, expected 1")
    ours, theirs = cfg.settings(), data["settings"]
    for key in ours:
        if key == "out" or (key in ("data", "init") and same_folder(ours[key], theirs.get(key))):
            continue
        if key in theirs and theirs[key] != ours[key]:
            raise AdaptError(
                f"{path}: the run was started with --{key.replace('_', '-')} {theirs[key]!r}, "
                f"not {ours[key]!r}; give the same settings or another --out"
            )
    try:
        check_payload(data["model"], path)
    except CheckpointError as exc:
        raise AdaptError(str(exc)) from exc
    memory = {
        sid: FrameMemory.from_arrays({k: v.numpy() for k, v in m.items()})
        for sid, m in data["memory"].items()
    }
    return RunFiles(
        model=data["model"],
        optimizer=data["optimizer"],
        progress=Progress(**data["progress"]),
        memory=memory,
        report=list(data["report"]),
        init_meta=dict(data["init_meta"]),
        rng=data["rng"],
    )


def adapted_meta(init_meta: dict[str, Any], cfg: AdaptConfig, rounds_done: int) -> CheckpointMeta:
    """The adapted checkpoint's metadata: the initial checkpoint's plus the lineage (module
    docstring)."""
    meta = CheckpointMeta.from_dict(init_meta)
    lineage = {
        "init": portable_path(cfg.init),
        "data": portable_path(cfg.data),
        "rounds_done": rounds_done,
        "rounds": cfg.rounds,
        "settings": cfg.settings(),
        "updated": "scene encoder and detector (batch-norm statistics too); text and referent "
        "stage as in init",
    }
    stage = (
        f"self-training adaptation (python -m model.adapt, {rounds_done} of {cfg.rounds} rounds) "
        f"of {lineage['init']} on the unlabelled frames of {lineage['data']}"
    )
    previous = meta.training_stages
    stages = stage if not previous else f"{previous}; then {stage}"
    extra = {**meta.extra, "adaptation": lineage}
    return meta.replace(training_stages=stages, extra=extra).with_portable_paths()


def model_payload(model: TPCNet, meta: CheckpointMeta) -> dict[str, Any]:
    """``model`` as a checkpoint payload with ``meta``."""
    return checkpoint_payload(model, **meta.to_dict())


__all__ = [
    "LAST_FILE",
    "REPORT_FILE",
    "STATE_FILE",
    "Progress",
    "RunFiles",
    "adapted_meta",
    "load_state",
    "model_payload",
    "round_file",
    "save_state",
    "state_path",
]
