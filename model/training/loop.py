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

One loop trains every stage; the step of the run's stage (the paper's path, the referent path's
joint stage or its ``--freeze-scene`` stage) is chosen once (:func:`choose_step`,
:mod:`model.training.steps`).

SIGINT or SIGTERM (:mod:`model.training.stop_signal`) let the current step finish, save the run state and
exit with 130 or 143 and one line. A non-finite loss or gradient stops training with a message
(exit 2); the last good checkpoint is kept as it was, and so is a training split without a box of
the three classes.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from model.checkpoint import checkpoint_payload, model_from_payload, write_payload
from model.checkpoint_meta import CheckpointMeta
from model.tpcnet import build_model
from model.training import distributed
from model.training.config import TrainConfig, TrainingError, parse_args
from model.training.data import MixedFrames, RootSpec, frame_dataset
from model.training.referent_cache import cached_referent_step
from model.training.referent_step import ReferentTrainConfig, referent_step
from model.training.state import (
    BEST_FILE,
    LAST_FILE,
    LOG_FILE,
    RunState,
    RunStateError,
    TrainState,
    check_resumable,
    load_run,
    rng_state,
    save_run,
    set_rng_state,
    state_path,
    trim_log,
)
from model.training.steps import (
    FrozenScenes,
    FrozenSceneStep,
    JointReferentStep,
    PaperStep,
    TrainStep,
    freeze_scene,
)
from model.training.stop_signal import StopRequest, TrainingInterrupted
from scenes.datasets.frames import FrameDataset, SensorAugment
from scenes.datasets.grounding import AugmentConfig, GroundingDataset
from scenes.geometry.actors import CLASSES
from scenes.talk2radar.kitti import read_label_file
from scenes.talk2radar.layout import LABEL, sample_dir, sample_file, split_file
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.scene_labels import SceneLabels, class_index
from scenes.utils.durable import append_json_line


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


def init_from(model: torch.nn.Module, path: str, prefixes: tuple[str, ...] = ()) -> int:
    """Copy every weight of the checkpoint at ``path`` whose name and shape match ``model``'s
    (e.g. the sensor branches, fusion, neck and head of a paper-path checkpoint into a referent
    model), only names starting with one of ``prefixes`` when given; a weight of
    :data:`WIDENABLE` that grew (the referent stage's geometry input with
    ``ReferentConfig.context`` or ``numeric_compare`` switched on, and its text gate) is copied
    into its first entries, the new ones zero (:func:`widened`). Returns how many tensors were copied."""
    from model.checkpoint import read_checkpoint

    state = read_checkpoint(path)["state_dict"]
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


def _log(out: Path, record: dict) -> None:
    append_json_line(out / LOG_FILE, record)


def validate(model: torch.nn.Module, cfg: TrainConfig, root: Talk2RadarRoot) -> dict:
    """3D mAP (entire area, 11-point) of ``model`` on the validation split."""
    from model.evaluation.report import evaluate_predictions  # late: only rank 0 validates

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


def check_labels(spec: RootSpec, split: str) -> None:
    """Refuse a training root none of whose ``split`` frames has a label of :data:`CLASSES` (its
    ``label_2``, or its scene labels' where given): it would train to nothing and report mAP 0."""
    root = Talk2RadarRoot(spec.path, radar=None)
    ids = root.ids(split)
    if not ids:
        raise TrainingError(f"{split_file(root.lidar_dir, split)}: split {split!r} is empty")
    scene = None if spec.scene_labels is None else SceneLabels(spec.scene_labels)
    for sid in ids:
        path = sample_file(root.lidar_dir, LABEL, sid) if scene is None else scene.label_path(sid)
        if path.is_file() and any(class_index(x.name) >= 0 for x in read_label_file(path)):
            return
    folder = sample_dir(root.lidar_dir if scene is None else scene.tree, LABEL)
    raise TrainingError(
        f"{folder}: no label of the {len(ids)} samples of split {split!r} has a "
        f"{', '.join(CLASSES)} box: nothing to train on"
    )


def _forward_step(model: torch.nn.Module, lidar: list, radar: list, prompts: list):
    return model(lidar, radar, prompts)


def choose_step(
    model: torch.nn.Module,
    cfg: TrainConfig,
    dataset: GroundingDataset | MixedFrames,
    referent_cfg: ReferentTrainConfig,
    frozen: FrozenScenes | None,
    device: torch.device,
) -> TrainStep:
    """The step of this run's stage (:mod:`model.training.steps`), its step function bound to
    ``model`` (looked up here when called, so that tests can wrap it)."""
    amp = cfg.amp == "bf16"
    if frozen is not None:
        step = distributed.wrap_step(model, cached_referent_step)
        return FrozenSceneStep(step, dataset, frozen, referent_cfg, cfg, device, amp)
    if cfg.grounding == "referent":
        step = distributed.wrap_step(model, referent_step)
        return JointReferentStep(step, dataset, referent_cfg, cfg.seed, device, amp)
    forward = distributed.wrap_step(model, _forward_step, find_unused=False)
    return PaperStep(forward, model, dataset, device, amp)


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
    out = Path(cfg.out)
    rank, world = distributed.rank(), distributed.world()
    device = distributed.local_device(torch.device(cfg.device))
    use_amp = cfg.amp == "bf16"
    if use_amp and device.type != "cuda":
        raise TrainingError("--amp bf16 runs on CUDA only (give --device cuda)")
    torch.manual_seed(cfg.seed + rank)
    radar_folder = None if cfg.radar_folder == "none" else cfg.radar_folder
    specs = cfg.roots()
    root = Talk2RadarRoot(specs[0].path, radar=radar_folder, sidecar=specs[0].scene_labels is None)
    for spec in specs:
        check_labels(spec, cfg.train_split)
    augment = AugmentConfig(flip_probability=cfg.flip_probability)
    referent = cfg.grounding == "referent"
    dataset: GroundingDataset | MixedFrames

    def frames_of(spec: RootSpec, **kwargs: object) -> FrameDataset:
        frames = frame_dataset(spec, cfg.train_split, **kwargs)
        if cfg.freeze_scene and cfg.scene_limit:
            frames.limit(cfg.scene_limit)  # the cached scenes (see below)
        return frames

    if referent:
        sensors = SensorAugment() if cfg.sensor_augment else None
        dataset = MixedFrames(
            [frames_of(spec, augment=augment, sensors=sensors, seed=cfg.seed) for spec in specs],
            [spec.weight for spec in specs],
            seed=cfg.seed,
        )
    else:
        dataset = GroundingDataset(root, cfg.train_split, augment=augment, seed=cfg.seed)
    referent_cfg = ReferentTrainConfig(cfg.prompt_draw())

    state = TrainState()
    run: RunState | None = None
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
    else:
        if resume:
            print(f"{out}: nothing to resume, starting a new run", file=sys.stderr)
        model = build_model(cfg.preset, **cfg.model_overrides())
        if cfg.init:
            copied = init_from(model, cfg.init)
            print(f"initialised {copied} weight tensors from {cfg.init}", file=sys.stderr)
        if cfg.init_detector:
            copied = init_from(model, cfg.init_detector, SCENE_MODULES)
            print(
                f"initialised the scene encoder and detector ({copied} tensors) from "
                f"{cfg.init_detector}; the referent stage starts from scratch",
                file=sys.stderr,
            )
    model.to(device)
    frozen = None
    if referent and cfg.freeze_scene:
        # Only the referent stage learns; every scene is encoded once by the frozen detector.
        roots = [functools.partial(frames_of, spec) for spec in specs]
        frozen = freeze_scene(model, cfg, roots, referent_cfg, progress=rank == 0)
    params = [p for p in model.parameters_in_checkpoint_order() if p.requires_grad]
    optimizer = torch.optim.AdamW(params, lr=cfg.lr, weight_decay=cfg.weight_decay, foreach=True)
    if run is not None:
        optimizer.load_state_dict(run.optimizer)
    step = choose_step(model, cfg, dataset, referent_cfg, frozen, device)

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
    ).with_portable_paths()

    def checkpoint(best: bool) -> None:
        """Every rank's RNG state to rank 0, which writes the run state and ``last.pt``; the
        other ranks wait until it is written."""
        if not distributed.same_on_every_rank(params):
            raise TrainingError(f"the {world} ranks hold different weights at step {state.step}")
        rngs = distributed.gather(rng_state())
        if rank == 0:
            meta = metadata.replace(step=state.step, epoch=state.epoch, val_mAP_3d=state.last_map)
            payload = checkpoint_payload(model, **meta.to_dict())
            schedule = {"total_steps": total_steps, "warmup": cfg.warmup_steps, "lr": cfg.lr}
            save_run(out, payload, optimizer.state_dict(), asdict(cfg), state, rngs, schedule)
            if best:
                write_payload(out / BEST_FILE, payload)
        distributed.barrier()

    def halt_if_asked() -> None:
        """At a step boundary: on a signal seen by any rank, save and stop (all ranks)."""
        signum = distributed.agree_max(stop.signum or 0)
        if signum:
            checkpoint(best=False)
            bar.close()
            raise TrainingInterrupted(
                signum,
                f"stopped after step {state.step} (epoch {state.epoch + 1}, batch "
                f"{state.step_in_epoch}); resumable state in {state_path(out)} (--resume)",
            )

    if run is not None and run.rng:
        set_rng_state(run.rng[rank])
    bar = tqdm(
        total=total_steps,
        initial=state.step,
        desc="train",
        unit="step",
        disable=rank != 0,
        dynamic_ncols=True,
    )
    start_time, seen = time.perf_counter(), 0
    last_epoch = min(cfg.epochs, cfg.stop_epoch) if cfg.stop_epoch else cfg.epochs
    with stop.deferred():
        while state.step < total_steps and state.epoch < last_epoch:
            dataset.set_epoch(state.epoch)
            batches = epoch_batches(
                len(dataset), cfg.batch_size, state.epoch, cfg.seed, rank, world
            )
            model.train()
            for indices in batches[state.step_in_epoch :]:
                if state.step >= total_steps:
                    break
                halt_if_asked()
                for group in optimizer.param_groups:
                    group["lr"] = cosine_lr(state.step, total_steps, cfg.lr, cfg.warmup_steps)
                loss = step(indices, state.epoch)
                terms, total, extra = loss.detection, loss.total, loss.extra
                if not total.requires_grad:  # no prompt in this shard: a zero-gradient step
                    total = total + sum(p.sum() * 0.0 for p in params)
                optimizer.zero_grad(set_to_none=True)
                total.backward()
                norm = torch.nn.utils.clip_grad_norm_(params, cfg.grad_clip)
                if not (torch.isfinite(total) and torch.isfinite(norm)):
                    raise TrainingError(
                        f"non-finite loss or gradient at step {state.step} (heatmap "
                        f"{terms.heatmap.item()}, regression {terms.regression.item()}, {extra}); "
                        f"the last good checkpoint in {out} is kept"
                    )
                optimizer.step()
                state.step += 1
                state.step_in_epoch += 1
                seen += len(indices) * world
                rate = seen / max(time.perf_counter() - start_time, 1e-9)
                bar.update(1)
                bar.set_postfix(loss=f"{total.item():.3f}", samples_s=f"{rate:.1f}", ep=state.epoch)
                if state.step % cfg.log_every == 0:
                    terms_logged = {"loss": total.item(), "heatmap": terms.heatmap.item()}
                    terms_logged.update(regression=terms.regression.item(), **extra)
                    means = distributed.mean(list(terms_logged.values()))
                    if rank == 0:
                        record = {"step": state.step, "epoch": state.epoch}
                        record.update(zip(terms_logged, means, strict=True))
                        lr = optimizer.param_groups[0]["lr"]
                        _log(out, {**record, "lr": lr, "samples_per_s": rate})
            else:
                state.epoch += 1
                state.step_in_epoch = 0
                best = False
                if rank == 0 and cfg.val_every and state.epoch % cfg.val_every == 0:
                    metrics = validate(model, cfg, root)
                    state.last_map = metrics["mAP_3d"]
                    best = state.last_map > state.best_map
                    state.best_map = max(state.best_map, state.last_map)
                    _log(out, {"step": state.step, "epoch": state.epoch, "val": metrics})
                    bar.write(f"epoch {state.epoch}: val 3D mAP {metrics['mAP_3d']:.2f}")
                checkpoint(best=best)
                continue
            break  # max_steps reached inside an epoch
        checkpoint(best=state.best_map < 0)
    bar.close()
    return state


def main(argv: list[str] | None = None) -> int:
    """The command: 0 when done, 2 on bad input or settings, 130 / 143 on SIGINT / SIGTERM."""
    try:
        cfg, resume = parse_args(argv)
    except TrainingError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rank, joined = distributed.launch_rank(), False
    try:
        joined = distributed.init_from_env(cfg.device)
        state = train(cfg, resume=resume)
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
            f"done: {state.step} steps, {state.epoch} epochs, best val 3D mAP {state.best_map:.2f}"
        )
        if cfg.grounding == "referent" and cfg.calibrate and state.epoch >= cfg.epochs:
            from model.training.calibrate import calibrate_run

            calibrate_run(Path(cfg.out) / LAST_FILE, cfg.roots()[0].path, cfg.val_split)
    return 0


if __name__ == "__main__":
    sys.exit(main())
