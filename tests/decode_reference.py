"""Reference outputs of decoding, candidate description and ``ground`` (issue 20): the inputs, the
outputs and their file. Not a test module; ``tests/model/test_decode_reference.py`` compares today's
code with the file.

Regenerate (only when a change of the outputs is intended, and say so in docs/RESULTS.md)::

    python -m tests.decode_reference

which rewrites :data:`REFERENCE` and records in it the commit it ran on (``commit``), the
generator version and torch's version; ``python -m tests.decode_reference --compare`` prints
how far the code as it is now is from the file, per kind of output. The committed file was
first made on the code before issue 20's speed-ups, then regenerated on its inference forms of the network (the change of
outputs between the two: docs/RESULTS_HISTORY.md, "Issue 20's inference forms"), and again when the
shipped checkpoint changed (its referent stage's weights; see ``commit`` in the file: the
last, stage 3i, was made on the model code of commit 2d4e681, before the inference fast paths of
``tests/model/test_inference_fast_paths.py``, which are held to it).

Inputs, all on this machine's CPU with one torch thread:

- frames: worlds :data:`WORLDS` of the synthetic generator (seed :data:`SEED`, a single radar
  scan, no camera; the default forward-half LiDAR, about 110k-135k points) and their prompts;
- the shipped checkpoint ``checkpoints/tpcnet-small.pt`` (referent path): per frame the
  candidates of ``encode_scene`` (boxes, labels, scores and every feature tensor) and
  ``ground`` of each prompt (boxes, scores, labels, in the order returned);
- an untrained ``small`` model (``torch.manual_seed(0)``), whose head is ~0.1 everywhere, so that
  hundreds of peaks reach rotated NMS: :func:`model.head.decode.decode` of its head output on the
  first frame at the head's threshold and at the candidate threshold.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import torch

from tests.paths import REPO, TEST_DATA

REFERENCE = TEST_DATA / "decode_reference.npz"
CHECKPOINT = REPO / "checkpoints" / "tpcnet-small.pt"
SEED = 3
WORLDS = (0, 1, 2)
PROMPTS = 2


def reference_frames() -> list[tuple[np.ndarray, np.ndarray, tuple[str, ...]]]:
    """``(lidar (N, 4), radar (M, 7), prompts)`` of each world of :data:`WORLDS`."""
    from scenes.geometry.calib import sensor_to_lidar, vod_lidar_calibration, vod_radar_calibration
    from scenes.synth.frame import SynthSettings, synthesize

    settings = SynthSettings(seed=SEED, radar_scans=1, prompts_per_world=PROMPTS, camera=None)
    radar_to_lidar = sensor_to_lidar(vod_lidar_calibration(), vod_radar_calibration())
    out = []
    for index in WORLDS:
        frame = synthesize(settings, index, radar_to_lidar)
        out.append(
            (
                np.ascontiguousarray(frame.lidar.points, dtype=np.float32),
                np.ascontiguousarray(frame.radar.points, dtype=np.float32),
                tuple(p.text for p in frame.prompts),
            )
        )
    return out


def _tensor(t: torch.Tensor | None) -> np.ndarray:
    return np.zeros((0, 0), np.float32) if t is None else t.detach().cpu().numpy()


def shipped_outputs(frames: list) -> dict[str, np.ndarray]:
    """Candidates and answers of the shipped checkpoint on ``frames`` (keys ``f<i>/...``)."""
    from model.checkpoint import load_checkpoint

    model = load_checkpoint(CHECKPOINT).eval()
    out: dict[str, np.ndarray] = {}
    for i, (lidar, radar, prompts) in enumerate(frames):
        features = model.encode_scene(lidar, radar)
        o = features.objects
        assert o is not None
        for name in ("boxes", "labels", "scores"):
            out[f"f{i}/cand_{name}"] = np.asarray(getattr(o, name))
        for name in ("geometry", "fused", "lidar", "radar"):
            out[f"f{i}/cand_{name}"] = _tensor(getattr(o, name))
        out[f"f{i}/prompts"] = np.array(prompts)
        for j, prompt in enumerate(prompts):
            pred = model.ground(features, prompt, ranked=True)
            out[f"f{i}/p{j}/boxes"] = pred.boxes
            out[f"f{i}/p{j}/scores"] = pred.scores
            out[f"f{i}/p{j}/labels"] = pred.labels
    return out


def untrained_outputs(frames: list) -> dict[str, np.ndarray]:
    """Decoded boxes of an untrained model's head on the first frame (many peaks)."""
    from model import build_model
    from model.head.decode import decode
    from model.tpcnet import as_points

    torch.manual_seed(0)
    model = build_model("small", grounding="referent").eval()
    lidar, radar, _ = frames[0]
    out: dict[str, np.ndarray] = {}
    with torch.no_grad():
        head, _ = model.detect([as_points(lidar, 4, "lidar")], [as_points(radar, 7, "radar")])
        cfg = model.cfg
        for key, threshold in (
            ("head", cfg.head.score_threshold),
            ("cand", cfg.referent.candidate_threshold),
        ):
            dets = decode(head, model.head_grid, cfg.head, threshold)[0]
            out[f"untrained/{key}/boxes"] = dets.boxes
            out[f"untrained/{key}/scores"] = dets.scores
            out[f"untrained/{key}/labels"] = dets.labels
    return out


def reference_outputs() -> dict[str, np.ndarray]:
    """Everything the reference file holds, from the code as it is now."""
    torch.set_num_threads(1)
    frames = reference_frames()
    return {**shipped_outputs(frames), **untrained_outputs(frames)}


def _commit() -> str:
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + (" (with uncommitted changes)" if dirty else "")


def compare() -> int:
    """Print, per kind of output, the largest absolute difference of the code as it is now from
    the stored reference (every discrete output must be equal: exit 1 otherwise)."""
    reference = dict(np.load(REFERENCE))
    current = reference_outputs()
    largest: dict[str, float] = {}
    unequal = []
    for key, want in reference.items():
        if "/" not in key:
            continue
        got = current[key]
        if want.dtype.kind in "iUb":
            if got.shape != want.shape or not np.array_equal(got, want):
                unequal.append(key)
            continue
        rest = key.split("/", 1)[1]  # (f<i>/cand_<x>, f<i>/p<j>/<x>, untrained/...)
        if key.startswith("untrained/"):
            kind = key
        else:
            kind = "answer " + rest.split("/", 1)[1] if "/" in rest else rest
        diff = float(np.abs(got - want).max()) if want.size else 0.0
        largest[kind] = max(largest.get(kind, 0.0), diff)
    print(f"against {REFERENCE.name} (commit {reference['commit']}):")
    for kind, diff in sorted(largest.items()):
        print(f"  {kind:32s} {diff:.1e}")
    print("discrete outputs: " + (f"DIFFER in {unequal}" if unequal else "all equal"))
    return 1 if unequal else 0


def main() -> int:
    if "--compare" in sys.argv[1:]:
        return compare()
    from scenes.synth.frame import GENERATOR_VERSION

    outputs = reference_outputs()
    meta = {
        "commit": np.array(_commit()),
        "generator_version": np.array(GENERATOR_VERSION),
        "torch_version": np.array(torch.__version__),
    }
    REFERENCE.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(REFERENCE, **outputs, **meta)
    print(f"wrote {REFERENCE} ({REFERENCE.stat().st_size} bytes, commit {meta['commit']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
