"""The detector's ceiling on a split's Talk2Car commands: ``python -m bench.talk2car_recall --data
NUSC [--split val] [--radar-sweeps 5] [--checkpoint checkpoints/tpcnet-small.pt]``.

For each kept command (``scenes.nuscenes.talk2car.read_commands``), whether the checkpoint's
detector proposes a box of the referent's class whose bird's-eye centre lies within the top-1
distance of the referent (1.0 m for a car, 0.5 m for a pedestrian or cyclist:
``model.evaluation.talk2car.metrics.TOP1_DISTANCE``): the share of commands a perfect referent
stage could answer. Printed overall and per class, with the candidates per sample.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

__all__ = ["detector_recall", "main"]


def detector_recall(
    data: Path, split: str, radar_sweeps: int, checkpoint: Path
) -> dict[str, tuple[int, int]]:
    """``class -> (commands whose referent is detected, commands)`` plus ``"all"``."""
    from model.checkpoint import load_checkpoint
    from model.evaluation.talk2car.metrics import TOP1_DISTANCE
    from scenes.nuscenes.root import NuScenesRoot
    from scenes.nuscenes.talk2car import read_commands

    root = NuScenesRoot(data, radar_sweeps=radar_sweeps)
    commands = read_commands(data / "commands", split, root)
    model = load_checkpoint(checkpoint)
    model.eval()
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
            hit = bool(((gaps < TOP1_DISTANCE[referent.cls]) & same).any())
            for key in ("all", referent.cls):
                counts.setdefault(key, [0, 0])
                counts[key][0] += hit
                counts[key][1] += 1
    return {k: (v[0], v[1]) for k, v in counts.items()}


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.talk2car_recall", description=__doc__)
    p.add_argument("--data", type=Path, required=True, help="nuScenes root with commands/")
    p.add_argument("--split", default="val")
    p.add_argument("--radar-sweeps", type=int, default=5)
    p.add_argument("--checkpoint", type=Path, default=Path("checkpoints/tpcnet-small.pt"))
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    counts = detector_recall(a.data, a.split, a.radar_sweeps, a.checkpoint)
    for key, (hit, n) in counts.items():
        print(
            f"{key:<10} referent detected within the top-1 distance: {hit}/{n} = {100 * hit / max(n, 1):.1f} %"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
