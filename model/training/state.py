"""The resumable state of a training run: one file, ``RUN/train_state.pt``, written atomically.

One :func:`save_run` writes everything a resumed run needs to go on exactly as if it had never
stopped, in one :func:`scenes.utils.durable.atomic_file` replace:

- ``model``: the model checkpoint (:func:`model.checkpoint.checkpoint_payload`: config, weights,
  metadata);
- ``optimizer``: the optimiser's ``state_dict``;
- ``schedule``: the planned total steps and warm-up (the learning rate is a pure function of the
  step, :func:`model.training.loop.cosine_lr`, so the step is the scheduler's whole state);
- ``progress``: :class:`TrainState`, whose ``epoch`` and ``step_in_epoch`` are the sampler's
  position (an epoch's batches are a permutation seeded by ``(seed, epoch)``,
  :func:`model.training.loop.epoch_batches`, and a resumed epoch skips its first ``step_in_epoch``);
- ``rng``: every random state of every rank (:func:`rng_state`: Python ``random``, NumPy's global
  generator, torch's CPU generator and, where CUDA is in use, every CUDA generator), one entry per
  rank in rank order. The NumPy generators of the datasets, the augmentations and the prompt
  generation are no state: each is created where it is used from ``(seed, epoch, item)`` or
  ``(seed, step, item)``, so the position restores them;
- ``world``: the number of processes that trained (a resume needs the same);
- ``config``: the run's :class:`model.training.loop.TrainConfig` as a dict.

``last.pt`` is derived: the same checkpoint payload, written (atomically) after the state file.
A resume reads the state file only and rewrites ``last.pt`` from it when a crash came between the
two writes, so the weights and the optimiser, schedule and RNG states a run resumes with always
belong to the same step: a torn pair cannot be resumed. A run folder of the older layout
(``train_state.pt`` without weights beside ``last.pt``) resumes when both hold the same step,
without RNG states (so not bit for bit); a torn pair of that layout (``last.pt`` of step 8 with the
state of step 4) is refused (:class:`RunStateError`).

On resume, :func:`trim_log` drops the records ``log.jsonl`` holds of steps after the saved one (a
run killed after logging steps it had not saved), so that the resumed run's log reads as an
uninterrupted run's.

Everything is plain data and tensors, so the file loads with ``torch.load(weights_only=True)``.
"""

from __future__ import annotations

import os
import random
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from model.checkpoint import (
    CheckpointError,
    check_payload,
    read_checkpoint,
    write_payload,
)
from model.checkpoint_meta import CheckpointMeta
from model.training.config import TrainConfig
from scenes.utils.cli import resumable_fields
from scenes.utils.durable import atomic_file, atomic_write_text, read_json_lines

STATE_FILE = "train_state.pt"
"""The run state in a run folder."""
LAST_FILE = "last.pt"
"""The latest model checkpoint in a run folder (derived from the state)."""
BEST_FILE = "best.pt"
"""The checkpoint of the best validation metric."""
LOG_FILE = "log.jsonl"
"""One JSON record per logged step and per validation."""
FORMAT = "talk2pc-train-state"
FORMAT_VERSION = 2
"""Version 1 (no ``format`` entry) held only config, progress and optimiser."""


class RunStateError(ValueError):
    """A run folder cannot be resumed; the message names the file and says why."""


@dataclass
class TrainState:
    """The mutable progress of a run.

    Attributes:
        epoch: Epochs completed.
        step: Optimiser steps completed (all epochs).
        step_in_epoch: Steps completed in the current epoch (the sampler's position).
        best_map: Best validation 3D mAP so far (-1: none).
        last_map: The last validation 3D mAP (None: none yet).
    """

    epoch: int = 0
    step: int = 0
    step_in_epoch: int = 0
    best_map: float = -1.0
    last_map: float | None = None


@dataclass(frozen=True)
class RunState:
    """A run folder's state as :func:`load_run` reads it.

    Attributes:
        config: The run's ``TrainConfig`` as a dict.
        progress: Where the run stands.
        model: The checkpoint payload (:func:`model.checkpoint.model_from_payload` builds it).
        optimizer: The optimiser's ``state_dict``.
        rng: One :func:`rng_state` per rank, in rank order; empty for the older layout.
        world: Processes that trained the run (1 for the older layout).
    """

    config: dict[str, Any]
    progress: TrainState
    model: dict[str, Any]
    optimizer: dict[str, Any]
    rng: tuple[dict[str, Any], ...]
    world: int


FREE_ON_RESUME = resumable_fields(TrainConfig)
"""Settings a resumed run may change (every other one must be the run's): the fields of
:class:`model.training.config.TrainConfig` marked ``on_resume``."""


PATH_SETTINGS = frozenset({"out", "data", "scene_labels"})
"""Settings that name folders (one, or one per root): a resume compares them by what they are
(the same folder), not by how they are spelled (``runs/a`` and ``/home/me/runs/a``)."""


def same_folder(a: object, b: object) -> bool:
    """Whether two spellings name the same file or folder: equal strings, the same inode
    (``os.path.samefile``, where both exist) or, where either does not exist, the same resolved
    path (relative to the working directory)."""
    if a == b:
        return True
    if not isinstance(a, str) or not isinstance(b, str):
        return False
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(a).resolve() == Path(b).resolve()


def _same_setting(key: str, ours: object, theirs: object) -> bool:
    if key not in PATH_SETTINGS or ours == theirs:
        return ours == theirs
    if isinstance(ours, list | tuple) and isinstance(theirs, list | tuple):
        return len(ours) == len(theirs) and all(map(same_folder, ours, theirs))
    return same_folder(ours, theirs)


def check_resumable(config: dict[str, Any], run: RunState, world: int) -> None:
    """Refuse to resume ``run`` with another ``config`` (but :data:`FREE_ON_RESUME`; folders
    compared by :func:`same_folder`) or another number of processes (the sampler's shards and the
    per-rank RNG states depend on it)."""
    out = config.get("out")
    changed = sorted(
        k
        for k, v in run.config.items()
        if k not in FREE_ON_RESUME and not _same_setting(k, config.get(k), v)
    )
    if changed:
        raise RunStateError(f"{out}: --resume with different settings: {changed}")
    if run.world != world:
        raise RunStateError(
            f"{out}: the run was trained by {run.world} process(es); resume it with as many "
            f"(this is {world})"
        )


def rng_state() -> dict[str, Any]:
    """Every global random state of this process, as plain data and tensors."""
    version, mt, gauss = random.getstate()
    legacy = np.random.get_state(legacy=False)
    cuda = None
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        cuda = [s.clone() for s in torch.cuda.get_rng_state_all()]
    return {
        "python": [version, list(mt), gauss],
        "numpy": {
            "key": [int(k) for k in legacy["state"]["key"]],
            "pos": int(legacy["state"]["pos"]),
            "has_gauss": int(legacy["has_gauss"]),
            "gauss": float(legacy["gauss"]),
        },
        "torch": torch.get_rng_state().clone(),
        "cuda": cuda,
    }


def set_rng_state(state: dict[str, Any]) -> None:
    """Restore what :func:`rng_state` captured (CUDA only where it was captured and is in use)."""
    version, mt, gauss = state["python"]
    random.setstate((version, tuple(mt), gauss))
    n = state["numpy"]
    np.random.set_state(
        {
            "bit_generator": "MT19937",
            "state": {"key": np.array(n["key"], dtype=np.uint32), "pos": n["pos"]},
            "has_gauss": n["has_gauss"],
            "gauss": n["gauss"],
        }
    )
    torch.set_rng_state(state["torch"])
    if state.get("cuda") is not None and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def state_path(out: str | os.PathLike[str]) -> Path:
    """``RUN/train_state.pt``."""
    return Path(out) / STATE_FILE


def save_run(
    out: str | os.PathLike[str],
    model: dict[str, Any],
    optimizer: dict[str, Any],
    config: dict[str, Any],
    progress: TrainState,
    rng: list[dict[str, Any]],
    schedule: dict[str, Any],
) -> None:
    """Write the run state (module docstring) in one atomic replace, then ``last.pt`` from the
    same ``model`` payload. ``rng`` holds one :func:`rng_state` per rank."""
    out = Path(out)
    record = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "config": config,
        "progress": asdict(progress),
        "model": model,
        "optimizer": optimizer,
        "schedule": schedule,
        "rng": list(rng),
        "world": len(rng),
    }
    with atomic_file(state_path(out)) as handle:
        torch.save(record, handle)
    write_payload(out / LAST_FILE, model)


def _read(path: Path) -> dict[str, Any]:
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise RunStateError(f"{path}: unreadable run state ({first})") from exc
    if not isinstance(data, dict):
        raise RunStateError(f"{path}: not a run state")
    return data


def _last_step(out: Path) -> int | None:
    try:
        step = CheckpointMeta.from_dict(read_checkpoint(out / LAST_FILE)["metadata"]).step
    except CheckpointError as exc:
        raise RunStateError(str(exc)) from exc
    return step if isinstance(step, int) else None


def load_run(out: str | os.PathLike[str], repair: bool = True) -> RunState:
    """The state of the run folder ``out`` (module docstring); with ``repair`` (rank 0),
    ``last.pt`` is rewritten from it when it lags behind (a crash between the two writes).

    Raises:
        RunStateError: no state file, an unreadable one, or a torn pair of the older layout.
    """
    out = Path(out)
    path = state_path(out)
    if not path.is_file():
        if (out / LAST_FILE).is_file():
            raise RunStateError(
                f"{out / LAST_FILE} has no {STATE_FILE} beside it: not a resumable run (start a "
                f"new one with --init {out / LAST_FILE})"
            )
        raise RunStateError(f"{path}: no run state to resume")
    data = _read(path)
    if data.get("format") == FORMAT:
        if data.get("format_version") != FORMAT_VERSION:
            raise RunStateError(
                f"{path}: run state version {data.get('format_version')!r}; this code reads "
                f"{FORMAT_VERSION}"
            )
        try:
            check_payload(data.get("model"), path)
        except CheckpointError as exc:
            raise RunStateError(str(exc)) from exc
        progress = TrainState(**data["progress"])
        if repair and (not (out / LAST_FILE).is_file() or _last_step(out) != progress.step):
            write_payload(out / LAST_FILE, data["model"])  # derived: bring it up to the state
        return RunState(
            data["config"],
            progress,
            data["model"],
            data["optimizer"],
            tuple(data["rng"]),
            int(data["world"]),
        )
    # The older layout: config, state and optimiser here, the weights in last.pt.
    if not {"config", "state", "optimizer"} <= set(data):
        raise RunStateError(f"{path}: not a run state (no progress or optimiser entry)")
    progress = TrainState(**data["state"])
    if not (out / LAST_FILE).is_file():
        raise RunStateError(f"{path}: {out / LAST_FILE} is missing; the weights cannot be resumed")
    last = _last_step(out)
    if last != progress.step:
        raise RunStateError(
            f"{out}: torn run: {LAST_FILE} holds step {last} but {STATE_FILE} step "
            f"{progress.step}; refusing to resume a mismatched pair (start a new run, or "
            f"--init {out / LAST_FILE})"
        )
    return RunState(
        data["config"], progress, read_checkpoint(out / LAST_FILE), data["optimizer"], (), 1
    )


def trim_log(out: str | os.PathLike[str], step: int) -> int:
    """Drop the records of ``out/log.jsonl`` of steps after ``step``, and unreadable (torn)
    lines; returns how many lines were dropped."""
    path = Path(out) / LOG_FILE
    log = read_json_lines(path)
    if not log.entries and not log.unreadable:
        return 0
    lines = path.read_text(encoding="utf-8", errors="replace").removeprefix("\ufeff").split("\n")
    keep = [
        lines[n - 1]
        for n, record in log.entries
        if not (isinstance(record, dict) and isinstance(record.get("step"), int))
        or record["step"] <= step
    ]
    dropped = len(log.entries) + len(log.unreadable) - len(keep)
    if dropped:
        atomic_write_text(path, "".join(line + "\n" for line in keep))
    return dropped


__all__ = [
    "BEST_FILE",
    "FORMAT",
    "FORMAT_VERSION",
    "FREE_ON_RESUME",
    "LAST_FILE",
    "LOG_FILE",
    "PATH_SETTINGS",
    "STATE_FILE",
    "RunState",
    "RunStateError",
    "TrainState",
    "check_resumable",
    "load_run",
    "rng_state",
    "same_folder",
    "save_run",
    "set_rng_state",
    "state_path",
    "trim_log",
]
