"""Train TPCNet: ``python -m model.train --data ROOT --out runs/NAME [options]``.

The paper's Talk2Radar settings (section IV-A): AdamW, learning rate 1e-3, weight decay 5e-4, a
cosine schedule (here per step, after a short linear warm-up), batch size 4. Gradients are clipped
at max-norm 35 (Talk2Radar's value). ``--amp bf16`` runs the forward passes under bfloat16
autocast (CUDA only; the losses stay in float32).

Several processes: ``torchrun --standalone --nproc_per_node N -m model.train ...`` trains every
path (the paper's, the referent path's joint stage and its ``--freeze-scene`` stage) with
DistributedDataParallel (:mod:`model.training.distributed`: ``gloo`` on CPU, ``nccl`` on GPUs); each rank
takes a disjoint shard of every epoch's permutation (``--batch-size`` is per rank), and only rank 0
writes checkpoints and logs.

Outputs in ``--out``: ``train_state.pt`` (:mod:`model.training.state`: weights, optimiser, schedule,
sampler position and every RNG state of every rank, one atomic file: what ``--resume`` needs),
``last.pt`` (derived from it) and ``best.pt`` (model checkpoints, :mod:`model.checkpoint`), and
``log.jsonl`` (one line per logged step and per validation; a resume drops the lines of steps
after the saved one). A resumed run repeats an
uninterrupted one bit for bit (on the CPU): the data order of epoch ``e`` is a permutation seeded
by ``(seed, e)``, augmentations and generated prompts are seeded per item, a resumed epoch skips
the batches already done, and the RNG states are restored.

One loop trains every stage: :func:`set_up` (the dataset, the frozen scenes and the step of
the run's grounding kind, chosen once: :mod:`model.training.kinds`, :mod:`model.training.steps`),
:func:`train_epochs` (:func:`train_step`, :func:`end_epoch`) and :func:`finish`.

One run writes ``--out`` at a time: :func:`main` holds its lock (:mod:`scenes.utils.run_lock`,
taken by rank 0 under ``torchrun``, :func:`model.training.distributed.folder_lock`) until the run
is calibrated; a second run on it exits 2 with one line naming the first. The training roots'
labels of classes outside the model's set are counted and said once at set-up
(:mod:`model.training.label_check`). Each step's wall time sets the rank watch's limit
(:mod:`model.training.rank_watch`).

SIGINT or SIGTERM (:mod:`model.training.stop_signal`) let the current step finish, save the run state and
exit with 130 or 143 and one line. A non-finite loss or gradient stops training with a message
(exit 2); the last good checkpoint is kept as it was, and so is a training split without a box of
the three classes.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from model.checkpoint import checkpoint_payload, write_payload
from model.checkpoint_meta import CheckpointMeta
from model.tpcnet import TPCNet
from model.training import distributed
from model.training.config import TrainConfig, TrainingError, parse_args
from model.training.kinds import TrainingData, TrainingKind, training_kind
from model.training.label_check import check_labels, outside_line
from model.training.referent_step import ReferentTrainConfig
from model.training.start import start_model
from model.training.state import (
    BEST_FILE,
    LAST_FILE,
    LOG_FILE,
    RunStateError,
    TrainState,
    rng_state,
    save_run,
    set_rng_state,
    state_path,
)
from model.training.steps import TrainStep
from model.training.stop_signal import StopRequest, TrainingInterrupted
from scenes.datasets.source import open_source
from scenes.frame import FrameSource
from scenes.geometry.classes import class_set
from scenes.utils.durable import append_json_line
from scenes.utils.run_lock import RunLockError


def cosine_lr(step: int, total: int, base: float, warmup: int) -> float:
    """Learning rate at ``step``: linear warm-up to ``base``, then cosine decay to ``base / 100``."""
    if warmup > 0 and step < warmup:
        return base * (step + 1) / warmup
    progress = min(1.0, (step - warmup) / max(1, total - warmup))
    floor = base * 0.01
    return floor + 0.5 * (base - floor) * (1.0 + math.cos(math.pi * progress))


def epoch_batches(n: int, batch_size: int, epoch: int, seed: int, rank: int, world: int) -> list:
    """This rank's batches (lists of dataset indices) of ``epoch``; the same on every resume.

    The epoch's permutation is seeded by ``(seed, epoch)``; it is truncated to a multiple of
    ``world * batch_size`` items (at least one batch per rank) and dealt out rank by rank.
    """
    order = np.random.default_rng((seed, epoch)).permutation(n)
    per_step = world * batch_size
    usable = max(per_step, (n // per_step) * per_step)
    order = np.resize(order, usable)  # repeats items only when n < one global batch
    mine = order[rank::world]
    return [mine[i : i + batch_size].tolist() for i in range(0, len(mine), batch_size)]


def _log(out: Path, record: dict) -> None:
    append_json_line(out / LOG_FILE, record)


def validate(model: torch.nn.Module, cfg: TrainConfig, root: FrameSource) -> dict:
    """3D mAP (entire area, 11-point) of ``model`` on the validation split."""
    from model.evaluation.talk2radar import evaluate_predictions  # late: only rank 0 validates

    ids = root.ids(cfg.val_split)
    if cfg.val_limit:
        ids = ids[: cfg.val_limit]
    report = evaluate_predictions(model, root, ids, progress=False)
    return {
        "mAP_3d": report.result.entire_area.map_3d,
        "mAP_bev": report.result.entire_area.map_bev,
        "roi_mAP_3d": report.result.roi.map_3d,
        "frames": len(ids),
    }


def train(cfg: TrainConfig, resume: bool = False) -> TrainState:
    """Run (or resume) a training run; returns the final state.

    Raises:
        TrainingError: bad data or settings, a non-finite loss.
        model.training.stop_signal.TrainingInterrupted: SIGINT / SIGTERM (the state is saved when steps
            had run; module docstring).
    """
    with StopRequest() as stop:
        return _train(cfg, resume, stop)


def _train(cfg: TrainConfig, resume: bool, stop: StopRequest) -> TrainState:
    """Set up (:func:`set_up`), train epoch by epoch (:func:`train_epochs`), finish
    (:func:`finish`); a signal waits for the step under way (``stop.deferred``)."""
    run = set_up(cfg, resume, stop)
    with stop.deferred():
        train_epochs(run)
        return finish(run)


@dataclass
class Run:
    """A run under way: what :func:`set_up` made, which :func:`train_epochs` and :func:`finish`
    use; ``state`` and ``bar`` change as it goes.

    Attributes:
        cfg: The run's settings.
        kind: How its grounding kind trains (:mod:`model.training.kinds`).
        rank, world: This process's rank and the number of processes.
        root: The first training root (validated on); None for a nuScenes root.
        dataset: The training items.
        model: The model, on its device.
        params: The parameters trained, in checkpoint order.
        optimizer: AdamW over ``params``.
        step: The step of the run's stage.
        total_steps: Steps of the whole run (``--epochs``, ``--max-steps``).
        metadata: The checkpoints' metadata less the progress.
        state: Progress (step, epoch, validation figures).
        stop: The signal handler.
        bar: The progress bar (rank 0 shows it).
    """

    cfg: TrainConfig
    kind: TrainingKind
    rank: int
    world: int
    root: FrameSource | None
    dataset: TrainingData
    model: TPCNet
    params: list[torch.nn.Parameter]
    optimizer: torch.optim.Optimizer
    step: TrainStep
    total_steps: int
    metadata: CheckpointMeta
    state: TrainState
    stop: StopRequest
    bar: tqdm

    @property
    def out(self) -> Path:
        return Path(self.cfg.out)

    def checkpoint(self, best: bool) -> None:
        """Every rank's RNG state to rank 0, which writes the run state and ``last.pt``; the
        other ranks wait until it is written."""
        state = self.state
        if not distributed.same_on_every_rank(self.params):
            raise TrainingError(
                f"the {self.world} ranks hold different weights at step {state.step}"
            )
        rngs = distributed.gather(rng_state())
        if self.rank == 0:
            meta = self.metadata.replace(
                step=state.step, epoch=state.epoch, val_mAP_3d=state.last_map
            )
            payload = checkpoint_payload(self.model, **meta.to_dict())
            schedule = {
                "total_steps": self.total_steps,
                "warmup": self.cfg.warmup_steps,
                "lr": self.cfg.lr,
            }
            config = asdict(self.cfg)
            save_run(self.out, payload, self.optimizer.state_dict(), config, state, rngs, schedule)
            if best:
                write_payload(self.out / BEST_FILE, payload)
        distributed.barrier()

    def halt_if_asked(self) -> None:
        """At a step boundary: on a signal seen by any rank, save and stop (all ranks)."""
        signum = distributed.agree_max(self.stop.signum or 0)
        if signum:
            self.checkpoint(best=False)
            self.bar.close()
            state = self.state
            raise TrainingInterrupted(
                signum,
                f"stopped after step {state.step} (epoch {state.epoch + 1}, batch "
                f"{state.step_in_epoch}); resumable state in {state_path(self.out)} (--resume)",
            )


def set_up(cfg: TrainConfig, resume: bool, stop: StopRequest) -> Run:
    """Everything before the first step: the device, the roots checked, the dataset of the run's
    grounding kind, the model (resumed or new), the frozen scenes, the optimiser, the step, the
    schedule's length, the metadata, the RNG states of a resumed run and the progress bar.

    Raises:
        TrainingError: bad data or settings.
    """
    out = Path(cfg.out)
    rank, world = distributed.rank(), distributed.world()
    device = distributed.local_device(torch.device(cfg.device))
    if cfg.amp == "bf16" and device.type != "cuda":
        raise TrainingError("--amp bf16 runs on CUDA only (give --device cuda)")
    kind = training_kind(cfg)
    kind.check(cfg)
    torch.manual_seed(cfg.seed + rank)
    radar_folder = None if cfg.radar_folder == "none" else cfg.radar_folder
    specs = cfg.roots()
    root = None
    if specs[0].talk2car is None:
        sidecar = specs[0].scene_labels is None
        root = open_source(  # a Talk2Radar root (a nuScenes one comes with its commands)
            specs[0].path, radar=radar_folder, sidecar=sidecar, classes=class_set(cfg.classes)
        )
    elif cfg.val_every:
        raise TrainingError(
            f"--data {specs[0].path} is a nuScenes root: validation during training reads a "
            "Talk2Radar root; give --val-every 0 and evaluate the run with python -m "
            "model.evaluate --data NUSC --talk2car CMDS (it is calibrated on the val commands "
            "at the end)"
        )
    for spec in specs:  # labels outside the model's class set: counted, said once
        dropped = check_labels(spec, cfg.train_split, class_set(cfg.classes))
        if dropped and rank == 0:
            print(
                outside_line(spec, cfg.train_split, dropped, class_set(cfg.classes)),
                file=sys.stderr,
            )
    dataset = kind.dataset(cfg, specs, root)
    referent_cfg = ReferentTrainConfig(cfg.prompt_draw())
    model, saved, state = start_model(cfg, resume, rank, world, device)
    model.to(device)
    frozen = kind.frozen(model, cfg, specs, referent_cfg, progress=rank == 0)
    params = [p for p in model.parameters_in_checkpoint_order() if p.requires_grad]
    optimizer = torch.optim.AdamW(params, lr=cfg.lr, weight_decay=cfg.weight_decay, foreach=True)
    if saved is not None:
        optimizer.load_state_dict(saved.optimizer)
    step = kind.step(model, cfg, dataset, referent_cfg, frozen, device)
    steps_per_epoch = len(epoch_batches(len(dataset), cfg.batch_size, 0, cfg.seed, rank, world))
    total_steps = cfg.epochs * steps_per_epoch
    if cfg.max_steps:
        total_steps = min(total_steps, cfg.max_steps)
    if rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    metadata = CheckpointMeta(
        train_config=asdict(cfg),
        data={
            "root": specs[0].path,
            "roots": [spec.path for spec in specs],
            "train_samples": len(dataset),
        },
        class_remap=CheckpointMeta.of(model).class_remap,
    ).with_portable_paths()
    if saved is not None and saved.rng:
        set_rng_state(saved.rng[rank])
    bar = tqdm(
        total=total_steps,
        initial=state.step,
        desc="train",
        unit="step",
        disable=rank != 0,
        dynamic_ncols=True,
    )
    return Run(
        cfg=cfg,
        kind=kind,
        rank=rank,
        world=world,
        root=root,
        dataset=dataset,
        model=model,
        params=params,
        optimizer=optimizer,
        step=step,
        total_steps=total_steps,
        metadata=metadata,
        state=state,
        stop=stop,
        bar=bar,
    )


def train_epochs(run: Run) -> None:
    """The loop: epochs from the saved position (a resumed epoch skips its batches already done)
    until ``total_steps`` or the last epoch (``--stop-epoch``); each step as
    :func:`train_step`, each finished epoch as :func:`end_epoch`."""
    cfg, state = run.cfg, run.state
    last_epoch = min(cfg.epochs, cfg.stop_epoch) if cfg.stop_epoch else cfg.epochs
    clock = _Throughput(time.perf_counter(), 0)
    while state.step < run.total_steps and state.epoch < last_epoch:
        run.dataset.set_epoch(state.epoch)
        batches = epoch_batches(
            len(run.dataset), cfg.batch_size, state.epoch, cfg.seed, run.rank, run.world
        )
        run.model.train()
        for indices in batches[state.step_in_epoch :]:
            if state.step >= run.total_steps:
                return  # max_steps reached inside an epoch
            run.halt_if_asked()
            train_step(run, indices, clock)
        end_epoch(run)


@dataclass
class _Throughput:
    """Samples trained since the run (re)started and when it did: the bar's samples per second."""

    start: float
    seen: int


def train_step(run: Run, indices: list[int], clock: _Throughput) -> None:
    """One optimiser step on this rank's batch ``indices``: the learning rate of the schedule,
    the stage's losses, backward, clipping (a non-finite loss or gradient stops the run), the bar
    and, every ``--log-every`` steps, the log line (terms averaged over the ranks)."""
    cfg, state, optimizer = run.cfg, run.state, run.optimizer
    began = time.perf_counter()
    for group in optimizer.param_groups:
        group["lr"] = cosine_lr(state.step, run.total_steps, cfg.lr, cfg.warmup_steps)
    loss = run.step(indices, state.epoch)
    terms, total, extra = loss.detection, loss.total, loss.extra
    if not total.requires_grad:  # no prompt in this shard: a zero-gradient step
        total = total + sum(p.sum() * 0.0 for p in run.params)
    optimizer.zero_grad(set_to_none=True)
    total.backward()
    norm = torch.nn.utils.clip_grad_norm_(run.params, cfg.grad_clip)
    if not (torch.isfinite(total) and torch.isfinite(norm)):
        raise TrainingError(
            f"non-finite loss or gradient at step {state.step} (heatmap "
            f"{terms.heatmap.item()}, regression {terms.regression.item()}, {extra}); "
            f"the last good checkpoint in {run.out} is kept"
        )
    optimizer.step()
    state.step += 1
    state.step_in_epoch += 1
    clock.seen += len(indices) * run.world
    rate = clock.seen / max(time.perf_counter() - clock.start, 1e-9)
    run.bar.update(1)
    run.bar.set_postfix(loss=f"{total.item():.3f}", samples_s=f"{rate:.1f}", ep=state.epoch)
    if state.step % cfg.log_every == 0:
        terms_logged = {"loss": total.item(), "heatmap": terms.heatmap.item()}
        terms_logged.update(regression=terms.regression.item(), **extra)
        means = distributed.mean(list(terms_logged.values()))
        if run.rank == 0:
            record = {"step": state.step, "epoch": state.epoch}
            record.update(zip(terms_logged, means, strict=True))
            lr = optimizer.param_groups[0]["lr"]
            _log(run.out, {**record, "lr": lr, "samples_per_s": rate})
    distributed.note_step(time.perf_counter() - began)  # the rank watch's limit follows it


def end_epoch(run: Run) -> None:
    """After an epoch's last batch: the next epoch's position, validation every ``--val-every``
    epochs (rank 0), the checkpoint (``best.pt`` too when the validation improved)."""
    cfg, state = run.cfg, run.state
    state.epoch += 1
    state.step_in_epoch = 0
    best = False
    if (
        run.rank == 0
        and run.root is not None
        and cfg.val_every
        and state.epoch % cfg.val_every == 0
    ):
        metrics = validate(run.model, cfg, run.root)
        state.last_map = metrics["mAP_3d"]
        best = state.last_map > state.best_map
        state.best_map = max(state.best_map, state.last_map)
        _log(run.out, {"step": state.step, "epoch": state.epoch, "val": metrics})
        run.bar.write(f"epoch {state.epoch}: val 3D mAP {metrics['mAP_3d']:.2f}")
    run.checkpoint(best=best)


def finish(run: Run) -> TrainState:
    """The last checkpoint (``best.pt`` too when the run never validated) and the final state."""
    run.checkpoint(best=run.state.best_map < 0)
    run.bar.close()
    return run.state


def main(argv: list[str] | None = None) -> int:
    """The command: 0 when done, 2 on bad input or settings, 130 / 143 on SIGINT / SIGTERM."""
    try:
        cfg, resume = parse_args(argv)
    except TrainingError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rank, joined = distributed.launch_rank(), False
    with contextlib.ExitStack() as held:  # --out's lock (scenes.utils.run_lock), until calibrated
        try:
            joined = distributed.init_from_env(cfg.device)
            held.enter_context(distributed.folder_lock(cfg.out))
            state = train(cfg, resume=resume)
        except RunLockError as exc:  # another run writes --out: rank 0 says who
            if str(exc):
                print(f"error: {exc}", file=sys.stderr)
            return 2
        except TrainingInterrupted as exc:
            if rank == 0:
                print(exc.message(), file=sys.stderr)
            return exc.exit_code
        except KeyboardInterrupt:  # before the handlers were installed
            print("interrupted by SIGINT: nothing new to save", file=sys.stderr)
            return 130
        except (TrainingError, RunStateError, ValueError, FileNotFoundError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        finally:
            if joined:
                distributed.close()
        if rank == 0:
            print(
                f"done: {state.step} steps, {state.epoch} epochs, best val 3D mAP "
                f"{state.best_map:.2f}"
            )
            if training_kind(cfg).calibrates and cfg.calibrate and state.epoch >= cfg.epochs:
                from model.training.calibrate import calibrate_run

                first = cfg.roots()[0]
                out = Path(cfg.out) / LAST_FILE
                calibrate_run(out, first.path, cfg.val_split, first.talk2car)
    return 0


if __name__ == "__main__":
    sys.exit(main())
