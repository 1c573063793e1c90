"""Class prompts over labelled boxes when the detector is wrong: ``python -m bench.studies.labelled_shift``.

Grounding over a frame's labelled boxes (``model.evaluate --candidates labels``, the app's
"Labelled boxes", the Annotate tab's sentence-first flow) must return the labelled objects of the
class asked for whatever the detector makes of the frame: on real View-of-Delft frames the
detector trained on our synthetic rig misses people the labels name (issue 37). This benchmark
asks "the cyclists", "the pedestrians" and "the cars" over the labelled (metric-class) boxes of
every frame of a root with full labels (a View-of-Delft-layout root, e.g. written by
``python -m scenes.export_real``) under three conditions of the detector:

- ``as is``: the frame as recorded;
- ``blind``: the detector's heatmap forced to zero (it proposes nothing and scores nothing: the
  extreme of "the detector does not see them"); the pooled map features stay;
- ``shifted sensor``: the frame as another rig would give it, which the detector never saw: half
  the LiDAR points dropped, their intensity halved, the LiDAR 0.3 m lower (points 0.3 m higher in
  its frame), two of every three radar points dropped. Not a training augmentation of ours.

Per class and pooled: the labelled objects of the class within ``--max-range`` (BEV, LiDAR
origin) and in the camera's view found by the answer (:func:`model.evaluation.class_prompt_counts.
count_prompt`: 3D IoU above the official minimum; a labelled box found is the box itself), and the
false boxes per prompt (answer boxes of the region that are not a labelled object of the class).
The code before issue 37 (commit c1d0ef7, the flat ``scenes/`` layout) is measured with this
file as first written (commit ae2aa4f), which imports that layout:
``git worktree add B c1d0ef7; git show ae2aa4f:bench/labelled_shift.py > B/bench/labelled_shift.py``,
then the same command in ``B`` (docs/RESULTS_HISTORY.md, "Labelled boxes").
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from model.evaluation.class_prompt_counts import (
    CLASS_PROMPTS,
    ClassSummary,
    ask_class_prompts,
    bev_range,
    other_label_boxes,
)
from scenes.geometry.calib import IMAGE_SIZE
from scenes.geometry.projection import in_camera_view
from scenes.utils.cli import command_parser, from_args, option

CONDITIONS = ("as is", "blind", "shifted sensor")
"""The detector conditions, in table order (module docstring)."""

BLIND_LOGIT = -30.0
"""The heatmap logit of a blind detector (sigmoid about 1e-13: nothing above any threshold)."""


@dataclass(frozen=True)
class SensorShift:
    """The ``shifted sensor`` condition: what another rig does to the clouds.

    Attributes:
        lidar_keep: Share of LiDAR points kept.
        intensity_scale: Factor on the LiDAR intensity.
        lidar_dz: Metres added to every LiDAR point's z (a sensor mounted that much lower).
        radar_keep: Share of radar points kept.
    """

    lidar_keep: float = 0.5
    intensity_scale: float = 0.5
    lidar_dz: float = 0.3
    radar_keep: float = 1.0 / 3.0

    def apply(
        self, lidar: np.ndarray, radar: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """Shifted copies of ``lidar (N, 4)`` and ``radar (M, 7)`` (LiDAR frame)."""
        lid = np.array(lidar, dtype=np.float32, copy=True)
        lid = lid[rng.random(len(lid)) < self.lidar_keep]
        lid[:, 2] += self.lidar_dz
        lid[:, 3] *= self.intensity_scale
        rad = np.asarray(radar, dtype=np.float32)
        return lid, rad[rng.random(len(rad)) < self.radar_keep].copy()


@contextlib.contextmanager
def blind_detector(model: torch.nn.Module) -> Iterator[None]:
    """``model``'s detector with its heatmap forced to :data:`BLIND_LOGIT` while in the block."""
    scene = model.scene
    original = scene.detector

    def blind(stages):
        neck, out = original(stages)
        return neck, type(out)(torch.full_like(out.heatmap, BLIND_LOGIT), out.regression)

    scene.detector = blind
    try:
        yield
    finally:
        del scene.detector


def frame_counts(
    model: torch.nn.Module, sample, condition: str, threshold: float, max_range: float
):
    """The three class prompts' :class:`PromptCount` on one sample of a full-labels root."""
    from model.core.labelled import LabelledBoxes

    gt_boxes = np.asarray(sample.boxes, dtype=np.float64).reshape(-1, 7)
    classes = model.cfg.class_set
    labels = [classes.index(c) for c in sample.classes]
    lidar, radar = sample.lidar, sample.radar
    if condition == "shifted sensor":
        rng = np.random.default_rng(int(sample.sample_id))
        lidar, radar = SensorShift().apply(lidar, radar, rng)
    blind = blind_detector(model) if condition == "blind" else contextlib.nullcontext()
    with blind:
        features = model.encode_scene(
            lidar, radar, candidates=LabelledBoxes(gt_boxes, labels, classes)
        )

    def counted(boxes: np.ndarray) -> np.ndarray:
        return (bev_range(boxes) <= max_range) & in_camera_view(boxes, sample.calib, IMAGE_SIZE)

    others = other_label_boxes(sample.labels, sample.calib)
    return ask_class_prompts(
        model, features, threshold, gt_boxes, sample.classes, counted, counted(gt_boxes), others
    )


def run(
    checkpoint: Path, root_dir: Path, max_range: float, limit: int, progress: bool
) -> dict[str, dict[str, dict]]:
    """``{condition: {class or 'all three': ClassSummary as a dict}}`` of one checkpoint."""
    from tqdm import tqdm

    from model.checkpoint import load_checkpoint
    from model.evaluation.predict import operating_threshold
    from scenes.datasets.family_files import labelled_frame_ids
    from scenes.talk2radar.root import Talk2RadarRoot

    model = load_checkpoint(checkpoint)
    model.eval()
    threshold = operating_threshold(model)
    root = Talk2RadarRoot(root_dir)
    ids = labelled_frame_ids(root, "all")
    ids = ids[:limit] if limit else ids
    counts: dict[str, list] = {c: [] for c in CONDITIONS}
    with torch.no_grad():
        for sid in tqdm(ids, desc=f"labelled shift {checkpoint.name}", disable=not progress):
            sample = root.load(sid)
            for cond in CONDITIONS:
                counts[cond] += frame_counts(model, sample, cond, threshold, max_range)
    table = {}
    for cond, rows in counts.items():
        per = {
            cls: asdict(ClassSummary.of([r for r in rows if r.cls == cls])) for cls in CLASS_PROMPTS
        }
        table[cond] = {**per, "all three": asdict(ClassSummary.of(rows))}
    return {"threshold": threshold, "frames": len(ids), "table": table}


def format_table(results: dict[str, dict]) -> str:
    """Markdown: one row per checkpoint and condition, recall % / false boxes per prompt."""
    heads = [*CLASS_PROMPTS.values(), "all three"]
    lines = [
        "| checkpoint | detector | " + " | ".join(heads) + " |",
        "| --- | --- | " + " | ".join("---:" for _ in heads) + " |",
    ]
    for name, res in results.items():
        for cond in CONDITIONS:
            row = res["table"][cond]
            cells = [
                f"{row[k]['recall']:.1f} / {row[k]['false_per_prompt']:.2f}"
                for k in (*CLASS_PROMPTS, "all three")
            ]
            lines.append(
                f"| {name} (threshold {res['threshold']:g}) | {cond} | " + " | ".join(cells) + " |"
            )
    return "\n".join(lines) + "\n"


@dataclass(frozen=True, kw_only=True)
class LabelledShiftOptions:
    """The flags of ``python -m bench.studies.labelled_shift``."""

    data: Path = option(help="a root with full labels (VoD layout)")
    checkpoint: tuple[Path, ...] = option(
        (),
        help="checkpoint to measure (repeat for several; default checkpoints/tpcnet-small.pt)",
    )
    max_range: float = option(30.0, help="metres, BEV (default %(default)s)")
    limit: int = option(0, help="first N frames only (0: all)")
    json: Path | None = option(None, help="write the figures here")
    quiet: bool = option(False, help="no progress bar")


def build_parser() -> argparse.ArgumentParser:
    return command_parser(
        "python -m bench.studies.labelled_shift", __doc__.split("\n")[0], LabelledShiftOptions
    )


def main(argv: Sequence[str] | None = None) -> int:
    args = from_args(LabelledShiftOptions, build_parser().parse_args(argv))
    checkpoints = list(args.checkpoint) or [Path("checkpoints/tpcnet-small.pt")]
    results = {
        str(c): run(c, args.data, args.max_range, args.limit, not args.quiet) for c in checkpoints
    }
    print(format_table(results), end="")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        command = " ".join(["python -m bench.studies.labelled_shift", *(argv or sys.argv[1:])])
        args.json.write_text(json.dumps({"command": command, **results}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
