"""Compare :mod:`model.evaluation.metrics` with the official View-of-Delft devkit on random non-degenerate sets.

The devkit (PyPI ``vod-tudelft``, which needs ``numba``) is not a project dependency. Install it in a
scratch virtual environment outside the repository and point this script at its interpreter::

    python3 -m venv /tmp/vodenv && /tmp/vodenv/bin/pip install vod-tudelft numba
    .venv/bin/python bench/devkit/compare_vod_devkit.py --devkit-python /tmp/vodenv/bin/python

The script writes random label / prediction folders (VoD-like camera, realistic projected 2D boxes,
noisy predictions with random scores, false positives, class confusions, flipped headings, small
and far objects), scores them with :func:`model.evaluation.files.score_directories`, runs the
devkit on the same folders in a subprocess (``bench/devkit/vod_devkit_worker.py``: the devkit is imported
only there, only when this script runs), and prints the largest absolute difference of every
reported number (R11 and R40; 3D, BEV, AOS; both areas).

The devkit (1.0.3) adds 0.01 rad to every detection's ``rotation_y`` and 0.01 px to its 2D box
before computing overlaps. Three comparisons are printed:

A. ours with ``devkit_offsets=True`` (the default) vs the devkit on the files as written: what
   ``python -m model.evaluate`` users get;
B. ours with ``devkit_offsets=False`` (exact overlaps of the boxes as written) vs the devkit given
   the prediction files with its offsets subtracted: the same geometry on both sides by another
   route;
C. ours with ``devkit_offsets=False`` vs the devkit on the files as written: the effect of the
   devkit's offsets (``--exact-overlaps``).

Measured with vod-tudelft 1.0.3 + numba 0.68.1 (seeds 0, 1, 2; 12 x 80, 20 x 100, 20 x 100
frames): A and B agree to 6e-14 AP points (summation order); C differs by up to 7 AP points.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

_REPO = Path(__file__).resolve().parents[2]
if str(_REPO) not in sys.path:
    sys.path.insert(0, str(_REPO))

from scenes.utils.cli import command_parser, option, run_command  # noqa: E402

_WORKER = Path(__file__).with_name("vod_devkit_worker.py")
"""The script the devkit's interpreter runs (:func:`bench.devkit.vod_devkit_worker.devkit_scores`)."""
_DEVKIT_OFFSET = 0.01  # the devkit's detection offsets: rotation_y + 0.01 rad, 2D box + 0.01 px


# ---------------------------------------------------------------------------------------------
# Random sets (project interpreter)

_SIZES = {  # mean l, w, h (m)
    "Car": (4.2, 1.8, 1.55),
    "Pedestrian": (0.7, 0.6, 1.75),
    "Cyclist": (1.8, 0.7, 1.7),
    "bicycle": (1.7, 0.6, 1.1),
    "rider": (0.7, 0.6, 1.7),
    "Van": (5.0, 2.0, 2.2),
    "Person_sitting": (0.8, 0.6, 1.2),
    "DontCare": (3.0, 3.0, 2.0),
}
# Van / Person_sitting are the devkit's neighbour classes and DontCare its don't-care regions; VoD
# has none of them, but they exercise those rules.
_GT_CLASSES = (
    "Car",
    "Pedestrian",
    "Cyclist",
    "bicycle",
    "rider",
    "Van",
    "Person_sitting",
    "DontCare",
)
_GT_PROBS = (0.33, 0.28, 0.24, 0.04, 0.04, 0.03, 0.02, 0.02)
_METRIC_CLASSES = ("Car", "Pedestrian", "Cyclist")
_DETECTED_AS = {
    "bicycle": "Cyclist",
    "rider": "Cyclist",
    "Van": "Car",
    "Person_sitting": "Pedestrian",
}


def _random_boxes(rng: np.random.Generator, classes: list[str]) -> np.ndarray:
    """LiDAR-frame boxes ``(K, 7)`` on the ground in the camera's field of view."""
    k = len(classes)
    depth = rng.uniform(3.0, 75.0, k)  # beyond ~50 m many 2D boxes fall under 40 px
    lateral = rng.uniform(-0.55, 0.55, k) * depth
    size = np.array([_SIZES[c] for c in classes]).reshape(k, 3) * rng.uniform(0.85, 1.15, (k, 3))
    z = -1.7 + size[:, 2] / 2.0
    yaw = rng.uniform(-np.pi, np.pi, k)
    return np.column_stack([depth, lateral, z, size, yaw])


def _noisy(rng: np.random.Generator, boxes: np.ndarray, level: float) -> np.ndarray:
    out = boxes.copy()
    scale = np.maximum(out[:, 3:5].min(axis=1), 0.5)[:, None]
    out[:, :2] += rng.normal(0.0, level * 0.35, (len(out), 2)) * scale
    out[:, 2] += rng.normal(0.0, level * 0.15, len(out))
    out[:, 3:6] *= rng.uniform(1.0 - level * 0.3, 1.0 + level * 0.3, (len(out), 3))
    out[:, 6] += rng.normal(0.0, 0.25, len(out))
    flip = rng.random(len(out)) < 0.1
    out[flip, 6] += np.pi
    return out


def make_random_set(folder: Path, seed: int, frames: int, level: float) -> None:
    """Write ``folder/labels``, ``folder/preds`` (as a model writes them, 4 decimals) and
    ``folder/devkit_preds`` (the same predictions with the devkit's offsets subtracted)."""
    from scenes.frame.kitti import ObjectLabel, boxes_to_labels, format_label_line, read_label_file
    from scenes.geometry.calib import vod_lidar_calibration

    rng = np.random.default_rng(seed)
    calib = vod_lidar_calibration()
    for sub in ("labels", "preds", "devkit_preds", "raw_preds"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    for f in range(frames):
        fid = f"{f:05d}"
        n = int(rng.integers(0, 9))
        classes = list(rng.choice(_GT_CLASSES, size=n, p=_GT_PROBS))
        boxes = _random_boxes(rng, classes)
        gt = boxes_to_labels(boxes, classes, calib)
        (folder / "labels" / f"{fid}.txt").write_text(
            "".join(format_label_line(lab) + "\n" for lab in gt)
        )
        keep = rng.random(n) < 0.85
        det_boxes = _noisy(rng, boxes[keep], level)
        det_classes = [
            _DETECTED_AS.get(c, c) if c != "DontCare" else str(rng.choice(_METRIC_CLASSES))
            for c in np.array(classes)[keep]
        ]
        confuse = rng.random(len(det_classes)) < 0.08
        det_classes = [
            str(rng.choice(_METRIC_CLASSES)) if c else name
            for c, name in zip(confuse, det_classes, strict=True)
        ]
        n_fp = int(rng.integers(0, 4))
        fp_classes = list(rng.choice(_METRIC_CLASSES, size=n_fp))
        det_boxes = np.concatenate([det_boxes, _random_boxes(rng, fp_classes)])
        det_classes += fp_classes
        scores = np.concatenate(
            [rng.uniform(0.2, 1.0, int(keep.sum())), rng.uniform(0.0, 0.8, n_fp)]
        )
        dets = boxes_to_labels(
            det_boxes, det_classes, calib, scores=scores, truncated=-1.0, occluded=-1
        )
        path = folder / "preds" / f"{fid}.txt"
        path.write_text("".join(format_label_line(lab) + "\n" for lab in dets))
        (folder / "raw_preds" / f"{fid}.txt").write_text(path.read_text())
        shifted = [
            ObjectLabel(
                name=lab.name,
                truncated=lab.truncated,
                occluded=lab.occluded,
                alpha=lab.alpha,
                bbox=tuple(v - _DEVKIT_OFFSET for v in lab.bbox),
                dimensions_hwl=lab.dimensions_hwl,
                location=lab.location,
                rotation_y=lab.rotation_y - _DEVKIT_OFFSET,
                score=lab.score,
            )
            for lab in read_label_file(path)
        ]
        (folder / "devkit_preds" / f"{fid}.txt").write_text(
            "".join(_full_precision_line(lab) + "\n" for lab in shifted)
        )


def _full_precision_line(lab) -> str:
    nums = [
        lab.truncated,
        lab.occluded,
        lab.alpha,
        *lab.bbox,
        *lab.dimensions_hwl,
        *lab.location,
        lab.rotation_y,
        lab.score,
    ]
    return " ".join(
        [lab.name, repr(float(nums[0])), str(int(nums[1]))] + [repr(float(v)) for v in nums[2:]]
    )


def _max_differences(ours: dict, devkit: dict) -> dict[str, float]:
    worst: dict[str, float] = {}
    for folder, theirs in devkit.items():
        mine = ours[folder]
        for area in ("entire_area", "roi"):
            for key, value in theirs[area].items():
                name = f"{area}/{key}"
                worst[name] = max(worst.get(name, 0.0), abs(mine[area][key] - value))
    return worst


@dataclass(frozen=True, kw_only=True)
class CompareVodOptions:
    """``bench/devkit/compare_vod_devkit.py``'s flags.

    Attributes:
        devkit_python: The interpreter of a virtual environment with the devkit installed.
        sets: Random sets written and scored.
        frames: Frames per set.
        seed: Set ``s`` is drawn with seed ``seed * 1000 + s``.
    """

    devkit_python: str = option("/tmp/vodenv/bin/python")
    sets: int = option(12, help="random sets")
    frames: int = option(80, help="frames per set")
    seed: int = option(0)


def build_parser() -> argparse.ArgumentParser:
    """``bench/devkit/compare_vod_devkit.py``'s parser (:class:`CompareVodOptions`)."""
    return command_parser(
        "python bench/devkit/compare_vod_devkit.py", __doc__.split("\n\n")[0], CompareVodOptions
    )


def _run(args: CompareVodOptions) -> int:
    """The command run as ``args`` says."""
    from model import score_directories

    with tempfile.TemporaryDirectory(prefix="vodcmp") as tmp:
        folders = []
        exact, emulated = {}, {}
        for s in range(args.sets):
            folder = Path(tmp) / f"set{s:02d}"
            level = (0.3, 0.6, 1.0)[s % 3]
            make_random_set(folder, seed=args.seed * 1000 + s, frames=args.frames, level=level)
            labels, preds = folder / "labels", folder / "preds"
            result = score_directories(labels, preds, devkit_offsets=False).result
            exact[f"{folder}|devkit_preds"] = result.to_dict()
            exact[f"{folder}|raw_preds"] = result.to_dict()
            emulated[f"{folder}|raw_preds"] = score_directories(labels, preds).result.to_dict()
            folders.append(str(folder))
        proc = subprocess.run(
            [args.devkit_python, str(_WORKER), *folders],
            capture_output=True,
            text=True,
            check=False,
        )
        if proc.returncode != 0:
            print(proc.stderr, file=sys.stderr)
            return 1
        devkit = json.loads(proc.stdout.strip().splitlines()[-1])

    compensated = {k: v for k, v in devkit.items() if k.endswith("|devkit_preds")}
    raw = {k: v for k, v in devkit.items() if k.endswith("|raw_preds")}
    comparisons = {
        "A: ours (default, devkit offsets) vs devkit, files as written": _max_differences(
            emulated, raw
        ),
        "B: ours (exact overlaps) vs devkit, offset-compensated files": _max_differences(
            exact, compensated
        ),
        "C: ours (exact overlaps) vs devkit, files as written": _max_differences(exact, raw),
    }
    values = [v for res in raw.values() for block in res.values() for v in block.values()]
    print(f"{args.sets} random sets x {args.frames} frames (seed {args.seed})")
    print(
        f"devkit numbers compared: {len(values)}, from {min(values):.2f} to {max(values):.2f} "
        f"(mean {np.mean(values):.2f})"
    )
    for title, worst in comparisons.items():
        print(f"\n{title}")
        print(f"  {'number':<34}{'max |ours - devkit|':>22}")
        for name in sorted(worst):
            print(f"  {name:<34}{worst[name]:>22.3e}")
        print(f"  overall max difference: {max(worst.values()):.3e} AP points")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    return run_command(build_parser(), CompareVodOptions, _run, argv)


if __name__ == "__main__":
    sys.exit(main())
