"""The settings of a training run (:class:`TrainConfig`) and the command line that builds them.

``python -m model.train --help`` lists every option; docs/DESIGN.md and docs/REAL_DATA.md say
how they combine. :class:`TrainConfig` is stored in every checkpoint and run state.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, fields
from pathlib import Path

import torch

from model.training.data import DataSpecError, RootSpec, root_specs


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
    amp: str = "none"
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
    label_prompts: int = 0
    calibrate: bool = True

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
        if self.amp not in ("none", "bf16"):
            raise TrainingError(f"--amp must be none or bf16, got {self.amp!r}")
        if self.grounding not in ("referent", "tpcnet"):
            raise TrainingError(f"--grounding must be referent or tpcnet, got {self.grounding!r}")
        if Path(self.out).exists() and not Path(self.out).is_dir():
            raise TrainingError(f"--out {self.out} is a file; give a run folder")

    def roots(self) -> tuple[RootSpec, ...]:
        """The training roots (:func:`model.training.data.root_specs`)."""
        return root_specs(self.data, self.data_weights, self.scene_labels)

    def model_overrides(self) -> dict[str, str]:
        """The ``build_model`` overrides given on the command line."""
        names = ("modalities", "fusion", "text_fusion", "anchor", "text_encoder", "grounding")
        return {n: getattr(self, n) for n in names if getattr(self, n) is not None}


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
    p.add_argument(
        "--amp",
        default="none",
        choices=["none", "bf16"],
        help="bf16: bfloat16 autocast of the forward passes (CUDA only)",
    )
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
        "--label-prompts",
        type=int,
        default=0,
        help="referent path, roots with --scene-labels: prompts generated per frame from its "
        "labelled boxes (class, depth and side only: their motion is unknown) beside the given "
        "one (default 0: given prompts only)",
    )
    p.add_argument(
        "--scene-limit",
        type=int,
        default=0,
        help="--freeze-scene: cache only the first N training scenes (0: all)",
    )
    p.add_argument(
        "--calibrate",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="referent path: at the end of the run, choose the operating threshold on the first "
        "root's validation split (python -m model.calibrate) and store it in last.pt (default: "
        "on; a split with too few referred prompts leaves it uncalibrated, with a notice)",
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
    given = {f.name: getattr(a, f.name) for f in fields(TrainConfig) if hasattr(a, f.name)}
    cfg = TrainConfig(
        **given, data_weights=tuple(a.data_weight), sensor_augment=not a.no_sensor_augment
    )
    return cfg, a.resume


__all__ = ["TrainConfig", "TrainingError", "parse_args"]
