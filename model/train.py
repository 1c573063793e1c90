"""Train TPCNet: ``python -m model.train --data ROOT --out runs/NAME [options]``.

The paper's Talk2Radar settings (section IV-A): AdamW, learning rate 1e-3, weight decay 5e-4, a
cosine schedule (here per step, after a short linear warm-up), batch size 4. Gradients are clipped
at max-norm 35 (Talk2Radar's value). On CUDA the forward pass runs under bfloat16 autocast (AMP).

Several processes: ``torchrun --nproc_per_node N -m model.train ...`` trains with
DistributedDataParallel (``gloo`` on CPU, ``nccl`` on GPUs); each rank sees a disjoint shard of every
epoch's permutation, and only rank 0 writes checkpoints and logs.

Outputs in ``--out``: ``last.pt`` and ``best.pt`` (model checkpoints, :mod:`model.checkpoint`),
``train_state.pt`` (optimizer, schedule, step, epoch, best metric: what ``--resume`` needs) and
``log.jsonl`` (one line per logged step and per validation). Resuming restarts at the exact step:
the data order of epoch ``e`` is a permutation seeded by ``(seed, e)``, augmentations are seeded
per item, and a resumed epoch skips the batches already done.

A non-finite loss stops training with a message; the last good checkpoint is kept as it was.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist
from torch.nn.parallel import DistributedDataParallel
from tqdm import tqdm

from model import build_model
from model.checkpoint import load_checkpoint, save_checkpoint
from model.losses import grounding_loss
from model.referent_train import (
    ReferentTrainConfig,
    TextBank,
    cache_scenes,
    cached_referent_step,
    referent_step,
)
from model.targets import collate_targets, draw_targets
from model.training_data import (
    DataSpecError,
    MixedFrames,
    RootSpec,
    frame_dataset,
    root_specs,
)
from scenes.dataset import AugmentConfig, GroundingBatch, GroundingDataset, collate
from scenes.durable import atomic_file
from scenes.frame_dataset import FrameDataset, SensorAugment
from scenes.root import Talk2RadarRoot


class TrainingError(RuntimeError):
    """Training cannot go on (bad data, non-finite loss); the message says why."""


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run (stored in the checkpoints)."""

    data: tuple[str, ...]
    out: str
    preset: str = "small"
    epochs: int = 20
    batch_size: int = 4
    lr: float = 1e-3
    weight_decay: float = 5e-4
    warmup_steps: int = 50
    grad_clip: float = 35.0
    modalities: str | None = None
    fusion: str | None = None
    text_fusion: str | None = None
    anchor: str | None = None
    text_encoder: str | None = None
    radar_folder: str = "auto"
    train_split: str = "train"
    val_split: str = "val"
    val_every: int = 1
    val_limit: int = 0
    seed: int = 0
    device: str = "cpu"
    amp: bool = True
    max_steps: int = 0
    stop_epoch: int = 0
    log_every: int = 10
    flip_probability: float = 0.5
    grounding: str = "referent"
    init: str | None = None
    prompts_per_scene: int = 8
    sensor_augment: bool = True
    freeze_scene: bool = False
    bank_prompts: int = 24
    scene_limit: int = 0
    data_weights: tuple[float, ...] = ()
    scene_labels: tuple[str, ...] = ()
    init_detector: str | None = None

    def __post_init__(self) -> None:
        for name in ("data", "data_weights", "scene_labels"):
            value = getattr(self, name)
            object.__setattr__(self, name, (value,) if isinstance(value, str) else tuple(value))
        try:
            self.roots()
        except DataSpecError as exc:
            raise TrainingError(str(exc)) from exc
        if self.init and self.init_detector:
            raise TrainingError("give --init or --init-detector, not both")
        if self.grounding != "referent" and (len(self.data) > 1 or self.scene_labels):
            raise TrainingError(
                "several --data roots and --scene-labels are the referent path's; the paper's "
                "path trains on one root's label_2 boxes"
            )
        for name in ("epochs", "batch_size", "prompts_per_scene"):
            if getattr(self, name) < 1:
                flag = "--" + name.replace("_", "-")
                raise TrainingError(f"{flag} must be >= 1, got {getattr(self, name)}")
        if self.grounding not in ("referent", "tpcnet"):
            raise TrainingError(f"--grounding must be referent or tpcnet, got {self.grounding!r}")
        if Path(self.out).exists() and not Path(self.out).is_dir():
            raise TrainingError(f"--out {self.out} is a file; give a run folder")

    def roots(self) -> tuple[RootSpec, ...]:
        """The training roots (:func:`model.training_data.root_specs`)."""
        return root_specs(self.data, self.data_weights, self.scene_labels)

    def model_overrides(self) -> dict[str, str]:
        """The ``build_model`` overrides given on the command line."""
        names = ("modalities", "fusion", "text_fusion", "anchor", "text_encoder", "grounding")
        return {n: getattr(self, n) for n in names if getattr(self, n) is not None}


@dataclass
class TrainState:
    """The mutable progress of a run (saved in ``train_state.pt``)."""

    epoch: int = 0
    step: int = 0
    step_in_epoch: int = 0
    best_map: float = -1.0
    last_map: float | None = None


def _rank() -> int:
    return dist.get_rank() if dist.is_available() and dist.is_initialized() else 0


def _world() -> int:
    return dist.get_world_size() if dist.is_available() and dist.is_initialized() else 1


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


def _targets(batch: GroundingBatch, model: torch.nn.Module, device: torch.device):
    cfg = model.cfg
    grid = model.head_grid
    return collate_targets(
        [
            draw_targets(b, c, grid, cfg.head)
            for b, c in zip(batch.boxes, batch.classes, strict=True)
        ]
    ).to(device)


SCENE_MODULES = ("lidar.", "radar.", "fusion.", "neck.", "head.")
"""Parameter-name prefixes of the scene encoder and detector (what ``--init-detector`` copies)."""


def init_from(model: torch.nn.Module, path: str, prefixes: tuple[str, ...] = ()) -> int:
    """Copy every weight of the checkpoint at ``path`` whose name and shape match ``model``'s
    (e.g. the sensor branches, fusion, neck and head of a paper-path checkpoint into a referent
    model), only names starting with one of ``prefixes`` when given; returns how many tensors
    were copied."""
    from model.checkpoint import read_checkpoint

    state = read_checkpoint(path)["state_dict"]
    own = model.state_dict()
    same = {
        k: v
        for k, v in state.items()
        if k in own and own[k].shape == v.shape and (not prefixes or k.startswith(prefixes))
    }
    if not same:
        raise TrainingError(f"{path}: no weight matches this model's names and shapes")
    model.load_state_dict(same, strict=False)
    return len(same)


def _log(out: Path, record: dict) -> None:
    with open(out / "log.jsonl", "a") as handle:
        handle.write(json.dumps(record) + "\n")


def validate(model: torch.nn.Module, cfg: TrainConfig, root: Talk2RadarRoot) -> dict:
    """3D mAP (entire area, 11-point) of ``model`` on the validation split."""
    from model.report import evaluate_predictions  # late: only rank 0 validates

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
    """Run (or resume) a training run; returns the final state."""
    out = Path(cfg.out)
    rank, world = _rank(), _world()
    device = torch.device(cfg.device)
    if device.type == "cuda" and world > 1:
        device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", 0)))
        torch.cuda.set_device(device)
    torch.manual_seed(cfg.seed + rank)
    radar_folder = None if cfg.radar_folder == "none" else cfg.radar_folder
    specs = cfg.roots()
    root = Talk2RadarRoot(specs[0].path, radar=radar_folder, sidecar=specs[0].scene_labels is None)
    augment = AugmentConfig(flip_probability=cfg.flip_probability)
    referent = cfg.grounding == "referent"
    dataset: GroundingDataset | MixedFrames

    def frames_of(spec: RootSpec, **kwargs: object) -> FrameDataset:
        frames = frame_dataset(spec, cfg.train_split, **kwargs)
        if cfg.freeze_scene and cfg.scene_limit:
            frames.limit(cfg.scene_limit)  # the cached scenes (see below)
        return frames

    if referent:
        if world > 1:
            raise TrainingError("the referent path trains in one process (no torchrun yet)")
        sensors = SensorAugment() if cfg.sensor_augment else None
        dataset = MixedFrames(
            [frames_of(spec, augment=augment, sensors=sensors, seed=cfg.seed) for spec in specs],
            [spec.weight for spec in specs],
            seed=cfg.seed,
        )
    else:
        dataset = GroundingDataset(root, cfg.train_split, augment=augment, seed=cfg.seed)
    referent_cfg = ReferentTrainConfig(prompts_per_scene=cfg.prompts_per_scene)

    state = TrainState()
    if resume and (out / "last.pt").is_file():
        model = load_checkpoint(out / "last.pt", device=str(device))
        saved = torch.load(out / "train_state.pt", map_location="cpu", weights_only=False)
        free = {
            "epochs",
            "max_steps",
            "stop_epoch",
            "val_every",
            "val_limit",
            "log_every",
            "device",
            "amp",
            "prompts_per_scene",
            "bank_prompts",
            "init",
            "init_detector",
        }
        now = asdict(cfg)
        changed = sorted(k for k, v in saved["config"].items() if k not in free and now.get(k) != v)
        if changed:
            raise TrainingError(f"{out}: --resume with different settings: {changed}")
        state = TrainState(**saved["state"])
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
        saved = None
    model.to(device)
    cached = None
    if referent and cfg.freeze_scene:
        # Only the referent stage learns; every scene is encoded once by the frozen detector.
        for name, p in model.named_parameters():
            p.requires_grad_(name.startswith("referent."))
        if cfg.text_encoder not in (None, "minilm"):
            raise TrainingError("--freeze-scene banks frozen MiniLM prompt features: use minilm")
        cached, bank = [], TextBank({})
        for spec in specs:
            part, part_bank = cache_scenes(
                model, frames_of(spec), cfg.bank_prompts, seed=cfg.seed, progress=rank == 0
            )
            cached += part
            bank.entries.update(part_bank.entries)
    params = [p for p in model.parameters() if p.requires_grad]
    optimizer = torch.optim.AdamW(params, lr=cfg.lr, weight_decay=cfg.weight_decay)
    if saved is not None:
        optimizer.load_state_dict(saved["optimizer"])
    wrapped: torch.nn.Module = model
    if world > 1:
        ids = [device.index] if device.type == "cuda" else None
        wrapped = DistributedDataParallel(model, device_ids=ids, find_unused_parameters=False)

    steps_per_epoch = len(epoch_batches(len(dataset), cfg.batch_size, 0, cfg.seed, rank, world))
    total_steps = cfg.epochs * steps_per_epoch
    if cfg.max_steps:
        total_steps = min(total_steps, cfg.max_steps)
    use_amp = cfg.amp and device.type == "cuda"
    if rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    metadata = {
        "train_config": asdict(cfg),
        "data": {
            "root": str(Path(specs[0].path).resolve()),
            "roots": [str(Path(spec.path).resolve()) for spec in specs],
            "train_samples": len(dataset),
        },
    }

    def checkpoint(best: bool) -> None:
        if rank != 0:
            return
        meta = dict(metadata, step=state.step, epoch=state.epoch, val_mAP_3d=state.last_map)
        save_checkpoint(out / "last.pt", model, **meta)
        with atomic_file(out / "train_state.pt") as handle:
            torch.save(
                {
                    "config": asdict(cfg),
                    "state": asdict(state),
                    "optimizer": optimizer.state_dict(),
                },
                handle,
            )
        if best:
            save_checkpoint(out / "best.pt", model, **meta)

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
    while state.step < total_steps and state.epoch < last_epoch:
        dataset.set_epoch(state.epoch)
        batches = epoch_batches(len(dataset), cfg.batch_size, state.epoch, cfg.seed, rank, world)
        model.train()
        for indices in batches[state.step_in_epoch :]:
            if state.step >= total_steps:
                break
            for group in optimizer.param_groups:
                group["lr"] = cosine_lr(state.step, total_steps, cfg.lr, cfg.warmup_steps)
            if cached is not None:
                step_rng = np.random.default_rng((cfg.seed, 7, state.step))
                picked = [cached[dataset.resolve(i)] for i in indices]
                ref = cached_referent_step(model, picked, bank, step_rng, referent_cfg)
                terms, total = ref.detection, ref.total
                extra = {"bce": ref.bce.item(), "listwise": ref.listwise.item()}
            elif referent:
                step_rng = np.random.default_rng((cfg.seed, 7, state.step))
                frames = [dataset[i] for i in indices]
                with torch.autocast(device_type=device.type, dtype=torch.bfloat16, enabled=use_amp):
                    ref = referent_step(model, frames, step_rng, referent_cfg)
                terms = ref.detection
                total = ref.total
                extra = {"bce": ref.bce.item(), "listwise": ref.listwise.item()}
            else:
                batch = collate([dataset[i] for i in indices])
                targets = _targets(batch, model, device)
                lidar = [t.to(device) for t in batch.lidar]
                radar = [t.to(device) for t in batch.radar]
                with torch.autocast(device_type=device.type, dtype=torch.bfloat16, enabled=use_amp):
                    output = wrapped(lidar, radar, list(batch.prompts))
                terms = grounding_loss(output, targets)
                total = terms.total
                extra = {}
            if not torch.isfinite(total):
                raise TrainingError(
                    f"non-finite loss at step {state.step} (heatmap {terms.heatmap.item()}, "
                    f"regression {terms.regression.item()}, {extra}); the last good checkpoint "
                    f"in {out} is kept"
                )
            optimizer.zero_grad(set_to_none=True)
            total.backward()
            torch.nn.utils.clip_grad_norm_(params, cfg.grad_clip)
            optimizer.step()
            state.step += 1
            state.step_in_epoch += 1
            seen += len(indices) * world
            rate = seen / max(time.perf_counter() - start_time, 1e-9)
            bar.update(1)
            bar.set_postfix(loss=f"{total.item():.3f}", samples_s=f"{rate:.1f}", ep=state.epoch)
            if rank == 0 and state.step % cfg.log_every == 0:
                _log(
                    out,
                    {
                        "step": state.step,
                        "epoch": state.epoch,
                        "loss": total.item(),
                        "heatmap": terms.heatmap.item(),
                        "regression": terms.regression.item(),
                        **extra,
                        "lr": optimizer.param_groups[0]["lr"],
                        "samples_per_s": rate,
                    },
                )
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
            if world > 1:
                dist.barrier()
            continue
        break  # max_steps reached inside an epoch
    checkpoint(best=state.best_map < 0)
    bar.close()
    return state


def parse_args(argv: list[str] | None = None) -> tuple[TrainConfig, bool]:
    """Parse the command line into a :class:`TrainConfig` and the resume flag."""
    p = argparse.ArgumentParser(prog="python -m model.train", description=__doc__.split("\n")[0])
    p.add_argument(
        "--data",
        required=True,
        action="append",
        help="Talk2Radar root; give it several times to train on several roots at once",
    )
    p.add_argument(
        "--data-weight",
        type=float,
        action="append",
        default=[],
        help="referent path: times each frame of the matching --data root (in order) is seen "
        "per epoch (default 1)",
    )
    p.add_argument(
        "--scene-labels",
        action="append",
        default=[],
        help="referent path: the View-of-Delft root whose label_2 lists every object of the "
        "matching --data root's frames (in order; 'none' for a root without); such a root trains "
        "on its labels and prompts only, never a sidecar",
    )
    p.add_argument("--out", required=True, help="run folder, e.g. runs/NAME")
    p.add_argument("--preset", default="small", choices=["small", "paper"])
    p.add_argument("--epochs", type=int, default=20)
    p.add_argument("--batch-size", type=int, default=4)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--weight-decay", type=float, default=5e-4)
    p.add_argument("--warmup-steps", type=int, default=50)
    p.add_argument("--modalities", choices=["lidar", "radar", "both"])
    p.add_argument(
        "--fusion", choices=["baca", "bi_mhca", "lidar_query", "radar_query", "conv_gate"]
    )
    p.add_argument("--text-fusion", choices=["dggf", "ggf"])
    p.add_argument("--anchor", choices=["corner", "edge", "center"])
    p.add_argument("--text-encoder", choices=["minilm", "gru"])
    p.add_argument(
        "--grounding",
        default="referent",
        choices=["referent", "tpcnet"],
        help="referent: text-agnostic detector + referent stage (default); tpcnet: the paper's "
        "DGGF + C3D-RECHead ranking",
    )
    p.add_argument(
        "--init", help="copy matching weights from this checkpoint before training (new runs)"
    )
    p.add_argument(
        "--init-detector",
        help="copy only the scene encoder and detector from this checkpoint; the referent stage "
        "starts from scratch (new runs)",
    )
    p.add_argument(
        "--prompts-per-scene",
        type=int,
        default=8,
        help="referent path: prompts generated per scene and step",
    )
    p.add_argument("--radar-folder", default="auto", help="radar tree, 'auto' or 'none'")
    p.add_argument("--val-every", type=int, default=1, help="validate every N epochs (0: never)")
    p.add_argument("--val-limit", type=int, default=0, help="validate on the first N frames only")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--no-amp", action="store_true", help="disable bfloat16 autocast on CUDA")
    p.add_argument("--max-steps", type=int, default=0, help="stop after N steps (0: all epochs)")
    p.add_argument(
        "--stop-epoch",
        type=int,
        default=0,
        help="stop after this many epochs but keep the --epochs learning-rate schedule "
        "(a budget cut; --resume without it goes on)",
    )
    p.add_argument("--log-every", type=int, default=10)
    p.add_argument("--flip-probability", type=float, default=0.5)
    p.add_argument(
        "--no-sensor-augment",
        action="store_true",
        help="referent path: no intensity / dropout / radar-count / single-scan augmentation",
    )
    p.add_argument(
        "--freeze-scene",
        action="store_true",
        help="referent path: train only the referent stage on scenes encoded once by the frozen "
        "detector (use with --init RUN/last.pt of a joint run)",
    )
    p.add_argument(
        "--bank-prompts",
        type=int,
        default=24,
        help="--freeze-scene: prompts generated and encoded once per scene",
    )
    p.add_argument(
        "--scene-limit",
        type=int,
        default=0,
        help="--freeze-scene: cache only the first N training scenes (0: all)",
    )
    p.add_argument("--resume", action="store_true", help="continue the run in --out")
    p.add_argument(
        "--threads",
        type=int,
        default=0,
        help="torch CPU threads (0: torch's default); use 1 when other jobs share the cores",
    )
    a = p.parse_args(argv)
    if a.threads:
        torch.set_num_threads(a.threads)
    cfg = TrainConfig(
        data=tuple(a.data),
        data_weights=tuple(a.data_weight),
        scene_labels=tuple(a.scene_labels),
        init_detector=a.init_detector,
        out=a.out,
        preset=a.preset,
        epochs=a.epochs,
        batch_size=a.batch_size,
        lr=a.lr,
        weight_decay=a.weight_decay,
        warmup_steps=a.warmup_steps,
        modalities=a.modalities,
        fusion=a.fusion,
        text_fusion=a.text_fusion,
        anchor=a.anchor,
        text_encoder=a.text_encoder,
        radar_folder=a.radar_folder,
        val_every=a.val_every,
        val_limit=a.val_limit,
        seed=a.seed,
        device=a.device,
        amp=not a.no_amp,
        max_steps=a.max_steps,
        stop_epoch=a.stop_epoch,
        log_every=a.log_every,
        flip_probability=a.flip_probability,
        grounding=a.grounding,
        init=a.init,
        prompts_per_scene=a.prompts_per_scene,
        sensor_augment=not a.no_sensor_augment,
        freeze_scene=a.freeze_scene,
        bank_prompts=a.bank_prompts,
        scene_limit=a.scene_limit,
    )
    return cfg, a.resume


def main(argv: list[str] | None = None) -> int:
    try:
        cfg, resume = parse_args(argv)
    except TrainingError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    distributed = int(os.environ.get("WORLD_SIZE", "1")) > 1
    if distributed:
        dist.init_process_group("nccl" if cfg.device.startswith("cuda") else "gloo")
    rank = int(os.environ.get("RANK", "0"))
    try:
        state = train(cfg, resume=resume)
    except (TrainingError, ValueError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    finally:
        if distributed:
            dist.destroy_process_group()
    if rank == 0:
        print(
            f"done: {state.step} steps, {state.epoch} epochs, best val 3D mAP {state.best_map:.2f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
