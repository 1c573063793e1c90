"""How close "carry to next frame" lands to the true boxes of the next frame:
``python -m bench.studies.carry_accuracy [--data SEQUENCE_ROOT] [--worlds 8] [--length 6] [--seed 7]``.

Without ``--data`` it writes a synthetic sequence root into a temporary folder (``python -m
scenes.synth --sequence-length LENGTH --prompts-per-world 1 --no-camera --seed SEED``, WORLDS
worlds) and measures on it. For every two consecutive frames of a drive (their poses
consecutive, :func:`scenes.talk2radar.poses.consecutive`) and every actor of the first frame inside the
annotated range with at least ``--min-points`` LiDAR points, its true box is carried to the next
frame by each method below and compared with the actor's true box there (same actor id in the
next frame's sidecar: the truth, which the carry itself never reads):

- ``in place``: the box copied with the same coordinates (what copying a pair does);
- ``ego``: moved by the ego motion between the two poses only;
- ``ego + radar``: and by its radar ground velocity (:func:`annotate.carry.carry_boxes` without
  the refit);
- ``ego + radar + refit (unknown speed)`` (the app's default): then refit to the next frame's
  points, keeping its size, where the radar could not tell its speed
  (:class:`annotate.carry.CarryConfig`);
- ``ego + radar + refit (always)``: every box refit.

Prints, per class and method, the number of boxes, the median and 90th percentile of the BEV
centre error and the share more than 0.5 m off.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

_REPO = Path(__file__).resolve().parents[2]
if str(_REPO) not in sys.path:
    sys.path.insert(0, str(_REPO))

from annotate.carry import CarryConfig, carry_boxes  # noqa: E402
from annotate.evidence import box_evidence  # noqa: E402
from scenes.frame import Sample  # noqa: E402
from scenes.geometry.actors import CLASSES  # noqa: E402
from scenes.synth.generate import SynthSettings, generate_root  # noqa: E402
from scenes.talk2radar.poses import FRAME_RATE, consecutive, lidar_motion, read_pose  # noqa: E402
from scenes.talk2radar.root import Talk2RadarRoot  # noqa: E402
from scenes.utils.cli import command_parser, option, run_command  # noqa: E402

METHODS = (
    "in place",
    "ego",
    "ego + radar",
    "ego + radar + refit (unknown speed)",
    "ego + radar + refit (always)",
)
"""The methods compared, in print order (see the module docstring)."""

MIN_POINTS = 5
"""LiDAR points an actor needs inside its box to be measured (``--min-points``)."""

X_RANGE, Y_RANGE = (0.0, 51.2), 25.6
"""The annotated range (:class:`annotate.ValidationConfig`'s defaults)."""


def frames(root: Talk2RadarRoot) -> list[Sample]:
    """One sample per distinct frame (:meth:`Talk2RadarRoot.frame_key`), in id order."""
    ids = sorted({sid for split in root.splits() for sid in root.ids(split)})
    out, seen = [], set()
    for sid in ids:
        key = root.frame_key(sid)
        if key not in seen:
            seen.add(key)
            out.append(root.load(sid))
    return out


def _in_range(box: np.ndarray) -> bool:
    return X_RANGE[0] <= box[0] <= X_RANGE[1] and abs(box[1]) <= Y_RANGE


def measure(
    root: Talk2RadarRoot, min_points: int = MIN_POINTS
) -> dict[str, dict[str, list[float]]]:
    """``errors[method][class]``: BEV centre errors (m) of every carried box."""
    errors: dict[str, dict[str, list[float]]] = {m: {c: [] for c in CLASSES} for m in METHODS}
    items = frames(root)
    dt = 1.0 / FRAME_RATE
    for a, b in itertools.pairwise(items):
        pose_a, pose_b = (
            read_pose(root.lidar_dir, a.sample_id),
            read_pose(root.lidar_dir, b.sample_id),
        )
        if pose_a is None or pose_b is None or not consecutive(pose_a, pose_b):
            continue
        if a.meta is None or b.meta is None:
            raise SystemExit(f"{root.path}: sample {a.sample_id} or {b.sample_id} has no sidecar")
        truth_b = {x.actor_id: x for x in b.meta.actors}
        actors = [
            x
            for x in a.meta.actors
            if x.actor_id in truth_b and _in_range(x.box) and _in_range(truth_b[x.actor_id].box)
        ]
        if not actors:
            continue
        boxes = np.array([x.box for x in actors])
        counts = [ev.lidar_points for ev in box_evidence(boxes, a.lidar, a.radar)]
        keep = [i for i, n in enumerate(counts) if n >= min_points]
        if not keep:
            continue
        boxes, actors = boxes[keep], [actors[i] for i in keep]
        classes = [x.cls for x in actors]
        motion = lidar_motion(pose_a, pose_b, a.calib)
        proposals = {
            "in place": boxes,
            "ego": np.array(
                [c.moved for c in carry_boxes(boxes, classes, np.zeros((0, 7)), motion, dt, None)]
            ),
            "ego + radar": np.array(
                [c.moved for c in carry_boxes(boxes, classes, a.radar, motion, dt, None)]
            ),
            **{
                f"ego + radar + refit ({how})": np.array(
                    [
                        c.box
                        for c in carry_boxes(
                            boxes, classes, a.radar, motion, dt, b.lidar, CarryConfig(refit=how)
                        )
                    ]
                )
                for how in ("unknown speed", "always")
            },
        }
        truth = np.array([truth_b[x.actor_id].box for x in actors])
        for method, carried in proposals.items():
            err = np.hypot(carried[:, 0] - truth[:, 0], carried[:, 1] - truth[:, 1])
            for cls, e in zip(classes, err, strict=True):
                errors[method][cls].append(float(e))
    return errors


def table(errors: dict[str, dict[str, list[float]]]) -> str:
    """The printed table (markdown)."""
    rows = [
        "| class | method | boxes | median (m) | p90 (m) | > 0.5 m |",
        "| --- | --- | ---: | ---: | ---: | ---: |",
    ]
    for cls in (*CLASSES, "all"):
        for method in METHODS:
            values = (
                [e for c in CLASSES for e in errors[method][c]]
                if cls == "all"
                else errors[method][cls]
            )
            if not values:
                continue
            v = np.asarray(values)
            rows.append(
                f"| {cls} | {method} | {len(v)} | {np.median(v):.2f} | "
                f"{np.percentile(v, 90):.2f} | {100.0 * np.mean(v > 0.5):.0f} % |"
            )
    return "\n".join(rows)


@dataclass(frozen=True, kw_only=True)
class CarryAccuracyOptions:
    """``python -m bench.studies.carry_accuracy``'s flags.

    Attributes:
        data: A sequence root to measure on (None: generate one).
        worlds: Worlds generated.
        length: Frames per world generated (``scenes.synth --sequence-length``).
        seed: The generator's seed.
        min_points: LiDAR points an actor needs to be measured.
    """

    data: Path | None = option(None, help="a sequence root (default: generate)")
    worlds: int = option(8, help="worlds generated (default %(default)s)")
    length: int = option(6, help="frames per world (default %(default)s)")
    seed: int = option(7, help="generator seed (default %(default)s)")
    min_points: int = option(MIN_POINTS, help="LiDAR points an actor needs")


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.studies.carry_accuracy``'s parser (:class:`CarryAccuracyOptions`)."""
    return command_parser(
        "python -m bench.studies.carry_accuracy", __doc__.splitlines()[0], CarryAccuracyOptions
    )


def _run(args: CarryAccuracyOptions) -> int:
    """The command run as ``args`` says."""
    with tempfile.TemporaryDirectory() as tmp:
        root_path = args.data
        if root_path is None:
            root_path = Path(tmp) / "sequences"
            settings = SynthSettings(
                seed=args.seed, prompts_per_world=1, camera=None, sequence_length=args.length
            )
            generate_root(root_path, args.worlds * args.length, settings, progress=True)
        errors = measure(Talk2RadarRoot(root_path), args.min_points)
    print(f"carry to the next frame (10 Hz) on {args.data or 'a generated sequence root'}:")
    print(table(errors))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    return run_command(build_parser(), CarryAccuracyOptions, _run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
