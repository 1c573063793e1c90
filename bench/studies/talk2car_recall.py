"""The detector's ceiling on a split's Talk2Car commands: ``python -m bench.talk2car_recall --data
NUSC [--split val] [--radar-sweeps 5] [--checkpoint CHECKPOINT]``.

For each kept command (``scenes.nuscenes.talk2car.read_commands``), whether the checkpoint's
detector proposes a box of the referent's class whose bird's-eye centre lies within the top-1
distance of the referent (1.0 m for a car, 0.5 m for a pedestrian or cyclist, other classes as
the class they are scored as: ``model.evaluation.talk2car.metrics.top1_distance``; the referents
read into the checkpoint's class set): the share of commands a perfect referent
stage could answer. Printed overall and per class, with the candidates per sample, and on the
rain, night and fog subsets of the scene descriptions
(``model.evaluation.talk2car.report.subset_of``).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from scenes.datasets.nuscenes_frames import RADAR_SWEEPS
from scenes.utils.cli import command_parser, option, run_command

__all__ = ["Talk2CarRecallOptions", "build_parser", "detector_recall", "main"]


def detector_recall(
    data: Path, split: str, radar_sweeps: int, checkpoint: Path
) -> dict[str, tuple[int, int]]:
    """``class -> (commands whose referent is detected, commands)`` plus ``"all"`` and each
    scene subset that holds commands (``"rain"``, ``"night"``, ``"fog"``)."""
    from model.checkpoint import load_checkpoint
    from model.evaluation.talk2car.metrics import top1_distance
    from model.evaluation.talk2car.report import subset_of
    from scenes.nuscenes.root import NuScenesRoot
    from scenes.nuscenes.talk2car import read_commands

    root = NuScenesRoot(data, radar_sweeps=radar_sweeps)
    model = load_checkpoint(checkpoint)
    model.eval()
    commands = read_commands(data / "commands", split, root, model.cfg.class_set)
    by_sample: dict[str, list] = {}
    for command in commands.commands:
        by_sample.setdefault(command.sample_token, []).append(command)
    counts: dict[str, list[int]] = {"all": [0, 0]}
    for token, cmds in by_sample.items():
        frame = root.frame(token)
        with torch.no_grad():
            objects = model.encode_scene(frame.lidar, frame.radar).objects
        boxes = np.asarray(objects.boxes, dtype=np.float64).reshape(-1, 7)
        labels = np.asarray(objects.labels).reshape(-1)
        for command in cmds:
            referent = commands.referent[command.command_token]
            gaps = np.hypot(*(boxes[:, :2] - referent.box[:2]).T)
            same = labels == model.cfg.class_set.index(referent.cls)
            hit = bool(((gaps < top1_distance(referent.cls)) & same).any())
            for key in (referent.cls, *subset_of(frame.description)):
                counts.setdefault(key, [0, 0])
                counts[key][0] += hit
                counts[key][1] += 1
    return {k: (v[0], v[1]) for k, v in counts.items()}


@dataclass(frozen=True, kw_only=True)
class Talk2CarRecallOptions:
    """``python -m bench.talk2car_recall``'s flags.

    Attributes:
        data: A nuScenes root with its Talk2Car ``commands/``.
        split: The commands' split.
        radar_sweeps: Radar sweeps accumulated per frame (default: what the model reads,
            :data:`scenes.datasets.nuscenes_frames.RADAR_SWEEPS`).
        checkpoint: The checkpoint whose detector is measured (None: the bundled one,
            ``model.DEFAULT_CHECKPOINT``).
    """

    data: Path = option(help="nuScenes root with commands/")
    split: str = option("val", help="the commands' split (default %(default)s)")
    radar_sweeps: int = option(
        RADAR_SWEEPS, help="radar sweeps a frame (default %(default)s, as the model reads)"
    )
    checkpoint: Path | None = option(
        None, help="a checkpoint (default: the bundled one, model.DEFAULT_CHECKPOINT)"
    )


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.talk2car_recall``'s parser (:class:`Talk2CarRecallOptions`)."""
    return command_parser("python -m bench.talk2car_recall", __doc__, Talk2CarRecallOptions)


def _run(a: Talk2CarRecallOptions) -> int:
    """The command run as ``a`` says."""
    torch.set_num_threads(1)
    from model import DEFAULT_CHECKPOINT

    checkpoint = DEFAULT_CHECKPOINT if a.checkpoint is None else a.checkpoint
    counts = detector_recall(a.data, a.split, a.radar_sweeps, checkpoint)
    for key, (hit, n) in counts.items():
        print(
            f"{key:<10} referent detected within the top-1 distance: {hit}/{n} = {100 * hit / max(n, 1):.1f} %"
        )
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    return run_command(build_parser(), Talk2CarRecallOptions, _run, argv)


if __name__ == "__main__":
    sys.exit(main())
