"""Several training processes (``torchrun``): process group, devices, collectives, DDP steps.

``torchrun --standalone --nproc_per_node N -m model.train ...`` starts ``N`` processes with
``RANK``, ``LOCAL_RANK`` and ``WORLD_SIZE`` set; :func:`init_from_env` joins them in one process
group (``gloo`` on the CPU, ``nccl`` on CUDA, each process on GPU ``LOCAL_RANK``). Every function
here is also right in one plain process (``world() == 1``): the collectives then return their
input and :func:`wrap_step` calls the step directly.

A training step of the referent path calls several of the model's methods (the detector, the
candidate description, the text encoder, the referent stage), not its ``forward``;
:class:`StepModule` makes the whole step one ``forward``, so that
:class:`~torch.nn.parallel.DistributedDataParallel` averages the gradients of every parameter the
step used over the ranks (unused ones, e.g. the referent stage of a rank whose scenes yielded no
prompt, count as zero: ``find_unused_parameters``).

A rank that stops answering (SIGSTOP, a hang) would hold the others in their next collective for
the process group's 30 minutes: every joined rank runs a heartbeat and a watch over the others
(:mod:`model.training.rank_watch`), which ends the run with one line naming the rank within
``TALK2PC_RANK_TIMEOUT`` seconds (default 60).
"""

from __future__ import annotations

import contextlib
import functools
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import torch
import torch.distributed as dist
from torch import nn
from torch.distributed import distributed_c10d
from torch.nn.parallel import DistributedDataParallel

from model.training.rank_watch import RankLiveness, RankWatch
from scenes.utils.cli import error_line
from scenes.utils.run_lock import RunLockError, run_lock


def launched() -> bool:
    """Whether this process was started by ``torchrun`` with more than one process."""
    return int(os.environ.get("WORLD_SIZE", "1")) > 1


def launch_rank() -> int:
    """The rank ``torchrun`` gave this process (0 in a plain process), before and after the
    process group."""
    return int(os.environ.get("RANK", "0"))


def init_from_env(device: str) -> bool:
    """Join the ``torchrun`` process group (``nccl`` for a CUDA ``device``, else ``gloo``);
    returns whether this call joined it (False in a plain process, or when already joined: the
    caller that joined closes it)."""
    if not launched() or active():
        return False
    global _WATCH
    liveness = RankLiveness.from_env()
    cuda = device.startswith("cuda")
    if cuda:
        torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", "0")))
    dist.init_process_group("nccl" if cuda else "gloo")
    store = distributed_c10d._get_default_store()
    _WATCH = RankWatch(store, dist.get_rank(), dist.get_world_size(), liveness).start()
    return True


_WATCH: RankWatch | None = None
"""This rank's heartbeat and watch over the others while a process group is joined
(:mod:`model.training.rank_watch`)."""


def close() -> None:
    """Leave the process group, if one was joined (the rank watch stopped first)."""
    global _WATCH
    if _WATCH is not None:
        _WATCH.stop()
        _WATCH = None
    if dist.is_available() and dist.is_initialized():
        dist.destroy_process_group()


def active() -> bool:
    """Whether a process group is joined."""
    return dist.is_available() and dist.is_initialized()


def rank() -> int:
    """This process's rank (0 in a plain process)."""
    return dist.get_rank() if active() else 0


def world() -> int:
    """The number of processes (1 in a plain process)."""
    return dist.get_world_size() if active() else 1


def local_device(device: torch.device) -> torch.device:
    """This process's device: CUDA device ``LOCAL_RANK`` under ``torchrun``, else ``device``."""
    if device.type == "cuda" and active():
        return torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
    return device


def _collective_device() -> torch.device:
    return (
        torch.device("cuda", torch.cuda.current_device())
        if dist.get_backend() == "nccl"
        else (torch.device("cpu"))
    )


def agree_max(value: int) -> int:
    """The largest ``value`` over the ranks (e.g. a pending signal number, 0 for none)."""
    if not active():
        return value
    t = torch.tensor([value], dtype=torch.int64, device=_collective_device())
    dist.all_reduce(t, op=dist.ReduceOp.MAX)
    return int(t.item())


def mean(values: list[float]) -> list[float]:
    """The mean over the ranks of each of ``values`` (for logging)."""
    if not active():
        return values
    t = torch.tensor(values, dtype=torch.float64, device=_collective_device())
    dist.all_reduce(t)
    return (t / world()).tolist()


def gather(obj: Any) -> list[Any]:
    """``obj`` of every rank, in rank order (every rank gets the list)."""
    if not active():
        return [obj]
    out: list[Any] = [None] * world()
    dist.all_gather_object(out, obj)
    return out


def same_on_every_rank(tensors: list[torch.Tensor]) -> bool:
    """Whether every rank holds the same ``tensors`` (compared by a float64 sum and sum of
    squares of each): DistributedDataParallel keeps the weights of all ranks identical, so a
    difference means that gradients were not averaged."""
    digest = [
        (float(t.detach().double().sum()), float(t.detach().double().square().sum()))
        for t in tensors
    ]
    return all(other == digest for other in gather(digest))


def barrier() -> None:
    """Wait for every rank."""
    if active():
        dist.barrier()


@contextlib.contextmanager
def folder_lock(folder: str | Path, what: str = "--out") -> Iterator[None]:
    """:func:`scenes.utils.run_lock.run_lock` on the run folder, taken by rank 0 alone (the one
    rank that writes it) for the ``with`` block; every rank learns whether it was taken. A
    refusal raises :class:`RunLockError` on every rank: rank 0's names the holder (the line to
    print), the others' is empty (so that one line is said)."""
    error: RunLockError | None = None
    with contextlib.ExitStack() as stack:
        if rank() == 0:
            try:
                stack.enter_context(run_lock(folder, what))
            except RunLockError as exc:
                error = exc
            except OSError as exc:
                error = RunLockError(
                    f"{folder}: the run folder cannot be locked: {error_line(exc)}"
                )
        if agree_max(int(error is not None)):
            raise error if error is not None else RunLockError("")
        yield


def note_step(seconds: float) -> None:
    """A training step took ``seconds`` (its wall time, collectives included): the rank watch
    sets its limit from it (:meth:`model.training.rank_watch.RankWatch.note_step`)."""
    if _WATCH is not None:
        _WATCH.note_step(seconds)


class StepModule(nn.Module):
    """A training step as a module: ``forward(*args)`` is ``step(model, *args)`` (module
    docstring). Its parameters are ``model``'s."""

    def __init__(self, model: nn.Module, step: Callable[..., Any]) -> None:
        super().__init__()
        self.model = model
        self.step = step

    def forward(self, *args: Any) -> Any:
        return self.step(self.model, *args)


def wrap_step(
    model: nn.Module, step: Callable[..., Any], find_unused: bool = True
) -> Callable[..., Any]:
    """``step`` bound to ``model``: called directly in a plain process, as the forward of a
    :class:`DistributedDataParallel` :class:`StepModule` under ``torchrun`` (gradients averaged
    over the ranks during ``backward``; the model's weights broadcast from rank 0 here)."""
    if not active():
        return functools.partial(step, model)
    return DistributedDataParallel(StepModule(model, step), find_unused_parameters=find_unused)


__all__ = [
    "StepModule",
    "active",
    "agree_max",
    "barrier",
    "close",
    "folder_lock",
    "gather",
    "init_from_env",
    "launch_rank",
    "launched",
    "local_device",
    "mean",
    "note_step",
    "rank",
    "same_on_every_rank",
    "world",
    "wrap_step",
]
