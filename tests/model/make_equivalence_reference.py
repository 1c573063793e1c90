"""Reference outputs of a checkpoint's whole pipeline on a tiny fixed synthetic root (issue 22).

Not a test module: ``tests/model/test_equivalence.py`` holds today's code to the files it writes, so
that a change of the model's shape (not of its arithmetic) is seen to keep every output::

    python tests/model/make_equivalence_reference.py --checkpoint checkpoints/tpcnet-small.pt \\
        --out tests/data/equivalence_small.npz

What it does, on the CPU with one torch thread:

1. writes a synthetic root (:func:`scenes.synth.generate_root`, seed :data:`SEED`,
   :data:`FRAMES` frames, one radar scan, no camera) into a temporary folder and reads its
   samples back with :class:`scenes.talk2radar.root.Talk2RadarRoot`;
2. keeps every :data:`STRIDE`-th LiDAR point of each frame (the file stays small) and stores the
   clouds and prompts as the *inputs*, so that the test does not depend on the generator;
3. per frame: ``detect`` (the text-agnostic detector: heatmap and regression checksums),
   ``encode_scene``, and per prompt ``ground`` at the default threshold (boxes, scores, labels,
   heatmap checksums) and at threshold 0 (every candidate's score: the referent probabilities of
   a referent-path model).

Only stable public entry points are used (``load_checkpoint``, ``encode_scene``, ``ground``,
``detect``), so the script runs on the code before and after a change of shape.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[2]
"""The repository root (this file runs as a script too: it puts the root on ``sys.path``)."""

if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

SEED = 11
FRAMES = 3
STRIDE = 6
"""Every ``STRIDE``-th LiDAR point is kept (the synthetic LiDAR has ~120k points a frame)."""


def reference_inputs() -> list[tuple[np.ndarray, np.ndarray, tuple[str, ...]]]:
    """``(lidar (N, 4), radar (M, 7) LiDAR frame, prompts)`` per frame of the fixed root."""
    from scenes.synth.generate import SynthSettings, generate_root
    from scenes.talk2radar.root import Talk2RadarRoot

    settings = SynthSettings(seed=SEED, radar_scans=1, prompts_per_world=2, camera=None)
    with tempfile.TemporaryDirectory() as tmp:
        root_dir = Path(tmp) / "root"
        generate_root(root_dir, FRAMES, settings, split_fractions=(0.0, 0.0, 1.0))
        root = Talk2RadarRoot(root_dir, radar="radar")
        by_scene: dict[bytes, tuple[np.ndarray, np.ndarray, list[str]]] = {}
        for split in ("train", "val", "test"):
            for sample_id in root.ids(split):
                s = root.load(sample_id)
                key = np.ascontiguousarray(s.lidar, dtype=np.float32).tobytes()
                entry = by_scene.setdefault(key, (s.lidar, s.radar, []))
                if s.prompt:
                    entry[2].append(s.prompt)
    out = []
    for lidar, radar, prompts in by_scene.values():
        out.append(
            (
                np.ascontiguousarray(lidar[::STRIDE], dtype=np.float32),
                np.ascontiguousarray(radar, dtype=np.float32),
                tuple(prompts),
            )
        )
    return out


def _checksums(maps: np.ndarray) -> np.ndarray:
    """``(C, 3)`` float64 per channel of ``(C, H, W)``: sum, sum of squares, position-weighted
    sum (catches a permutation of cells that keeps the first two)."""
    maps = np.asarray(maps, dtype=np.float64)
    c = maps.shape[0]
    flat = maps.reshape(c, -1)
    weights = np.arange(flat.shape[1], dtype=np.float64) / flat.shape[1]
    return np.stack([flat.sum(1), (flat**2).sum(1), (flat * weights).sum(1)], axis=1)


def pipeline_outputs(
    model: torch.nn.Module, inputs: list[tuple[np.ndarray, np.ndarray, tuple[str, ...]]]
) -> dict[str, np.ndarray]:
    """Every output the file stores, keyed ``f{frame}_...`` / ``f{frame}_p{prompt}_...``."""
    out: dict[str, np.ndarray] = {}
    model.eval()
    with torch.no_grad():
        for f, (lidar, radar, prompts) in enumerate(inputs):
            head, _ = model.detect([torch.from_numpy(lidar)], [torch.from_numpy(radar)])
            out[f"f{f}_detect_heatmap"] = _checksums(torch.sigmoid(head.heatmap[0]).numpy())
            out[f"f{f}_detect_regression"] = _checksums(head.regression[0].numpy())
            features = model.encode_scene(lidar, radar)
            for p, prompt in enumerate(prompts):
                pred = model.ground(features, prompt, ranked=True)
                key = f"f{f}_p{p}"
                out[f"{key}_boxes"] = np.asarray(pred.boxes, dtype=np.float64).reshape(-1, 7)
                out[f"{key}_scores"] = np.asarray(pred.scores, dtype=np.float64)
                out[f"{key}_labels"] = np.asarray(pred.labels, dtype=np.int64)
                out[f"{key}_heatmaps"] = _checksums(pred.heatmaps)
                every = model.ground(features, prompt, score_threshold=0.0, ranked=True)
                out[f"{key}_all_scores"] = np.asarray(every.scores, dtype=np.float64)
                out[f"{key}_all_labels"] = np.asarray(every.labels, dtype=np.int64)
    return out


def input_arrays(
    inputs: list[tuple[np.ndarray, np.ndarray, tuple[str, ...]]],
) -> dict[str, np.ndarray]:
    """The inputs as npz entries (``input{f}_lidar``, ``input{f}_radar``, ``input{f}_prompts``)."""
    out: dict[str, np.ndarray] = {"frames": np.array(len(inputs))}
    for f, (lidar, radar, prompts) in enumerate(inputs):
        out[f"input{f}_lidar"] = lidar
        out[f"input{f}_radar"] = radar
        out[f"input{f}_prompts"] = np.array(prompts, dtype=np.str_)
    return out


def read_inputs(
    data: dict[str, np.ndarray],
) -> list[tuple[np.ndarray, np.ndarray, tuple[str, ...]]]:
    """The inputs stored by :func:`input_arrays`."""
    return [
        (
            data[f"input{f}_lidar"],
            data[f"input{f}_radar"],
            tuple(str(p) for p in data[f"input{f}_prompts"]),
        )
        for f in range(int(data["frames"]))
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", required=True, help="checkpoint to run")
    parser.add_argument("--out", required=True, help="npz file to write")
    parser.add_argument(
        "--inputs",
        help="take the inputs stored in this npz (an earlier reference) instead of generating "
        "them: the outputs again after an intended change of arithmetic, on the same inputs",
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    from model.checkpoint import load_checkpoint

    inputs = read_inputs(dict(np.load(args.inputs))) if args.inputs else reference_inputs()
    model = load_checkpoint(args.checkpoint)
    arrays = {**input_arrays(inputs), **pipeline_outputs(model, inputs)}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(args.out, **arrays)
    sizes = [len(p) for _, _, p in inputs]
    print(f"{args.out}: {len(inputs)} frames, prompts per frame {sizes}, {len(arrays)} arrays")
    return 0


if __name__ == "__main__":
    sys.exit(main())
