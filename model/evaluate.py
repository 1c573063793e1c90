"""Command line for the official View-of-Delft evaluation (:mod:`model.evaluation.metrics`).

``python -m model.evaluate --labels DIR --preds DIR [--json OUT]`` scores KITTI-format prediction
files (``<frame id>.txt``, one detection per line with a 16th score field) against label files.
``python -m model.evaluate --data ROOT`` grounds a split (default ``test``) with a checkpoint (default
the bundled one), writes and scores its prediction files, and adds the per-prompt grounding metrics
(:mod:`model.evaluation.grounding`) with the class-noun and language-blind oracle baselines beside them.
``--data NUSC --talk2car NUSC/commands`` grounds a nuScenes root's Talk2Car commands instead
(table II, ``OUT/{split}_predictions.json``). Both go through one pipeline
(:mod:`model.evaluation.pipeline`) with the root's kind as its plug-in (:func:`evaluation_kind`);
files mode reads and scores written folders (:mod:`model.evaluation.files`). This module is the
command line: its flags (:class:`EvaluateConfig`), its modes and which one runs.

Decisions (the devkit behaves differently, see the spec §2.2):

- The frame list comes from the LABEL folder (every ``*.txt`` in it, not recursive). A frame whose
  prediction file is missing counts as a frame with no detections, so its ground truth counts as
  missed; the devkit would drop the frame instead and inflate AP.
- A prediction file for a frame with no label file is an error naming the file(s): it almost always
  means the wrong label folder or split.
- Overlaps follow the devkit, including its +0.01 rad / +0.01 px offsets on detections
  (``--exact-overlaps`` turns them off; see :mod:`model.evaluation.metrics`).
- A malformed prediction line is an error naming the file and line, and so is a prediction line
  without its score (the devkit would score it 0, silently ranking it last).
- Nothing that could silently change a score passes: every ``*.txt`` entry of both folders must be
  a readable file named by a zero-padded 5-digit frame id (``2.txt`` beside ``00002.txt`` would be
  one frame twice; a symlink loop would drop a frame), unreadable, non-UTF-8 and binary files are
  errors naming the file, and class names that are neither scored nor known (a typo such as
  ``Cyclst``) stay out of the metric, as the protocol says, but are counted and reported (the
  table's last line and a warning on stderr).
- Referents of classes outside the checkpoint's class set (a ``Truck`` on a three-class root, the
  bicycles of a ``--classes nuscenes`` root for the three-class checkpoint) are counted and named
  in one line after the tables and in the JSON's ``outside_class_set``; a prompt whose referents
  all lie outside the set is reported apart, never scored as an empty-answer prompt, and one with
  some keeps them as referents the model cannot answer (:mod:`model.evaluation.outside_classes`).
- Every error is one line on stderr, ``error: ...``, and exit code 2; a prediction worker
  (``--workers``) that dies or stops answering too (:mod:`model.evaluation.worker_watch`: within
  ``--worker-timeout`` and the measured time per frame; which worker, which frame, what to do),
  and then no prediction file or JSON is written.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from model.checkpoint import DEFAULT_CHECKPOINT
from model.config import ClassSetName
from model.evaluation.files import score_directories
from model.evaluation.grounding import CandidateSource
from model.evaluation.pipeline import EvaluationKind, run_evaluation, write_json
from model.evaluation.worker_watch import PredictionWorkerError
from scenes.geometry.classes import class_set
from scenes.utils.cli import command_parser, from_args, option, report_errors

DEFAULT_EVAL_DIR = Path("runs") / "eval"
"""Model mode's default output folder's parent (relative to the working directory)."""


FILES_MODE = "score prediction files"
"""The argument group of files mode (``--labels``, ``--preds``)."""

MODEL_MODE = "ground a split with a checkpoint, then score it"
"""The argument group of model mode (``--data`` and its settings)."""


@dataclass(frozen=True, kw_only=True)
class EvaluateConfig:
    """The settings of ``python -m model.evaluate`` (each field is one of its flags,
    :mod:`scenes.utils.cli`): files mode (``labels`` and ``preds``) or model mode (``data``)."""

    labels: Path | None = option(
        None, group=FILES_MODE, help="folder of ground-truth label_2 files"
    )
    preds: Path | None = option(
        None,
        group=FILES_MODE,
        help="folder of prediction files <frame id>.txt (a missing file = no detections)",
    )
    classes: ClassSetName = option(
        "vod",
        group=FILES_MODE,
        help="the class set scored, a row per class (vod: Car, Pedestrian, Cyclist; nuscenes: "
        "the 10 detection classes); model mode scores the checkpoint's own",
    )
    data: Path | None = option(
        None, group=MODEL_MODE, help="Talk2Radar root, or a nuScenes root with --talk2car"
    )
    talk2car: Path | None = option(
        None,
        group=MODEL_MODE,
        help="the Talk2Car command folder ({split}_commands.json) of the nuScenes --data root: "
        "ground its commands, print table II and write OUT/{split}_predictions.json",
    )
    split: str = option("test", group=MODEL_MODE, help="ImageSets split (default: test)")
    checkpoint: Path = option(
        DEFAULT_CHECKPOINT,
        group=MODEL_MODE,
        help="model checkpoint (.pt; default: the bundled checkpoints/tpcnet-small.pt)",
    )
    out: Path | None = option(
        None,
        group=MODEL_MODE,
        help=(
            f"folder for the prediction files (default: {DEFAULT_EVAL_DIR}/<root name>-<split>, "
            "with the JSON beside it as <that folder>.json unless --json is given)"
        ),
    )
    threshold: float | None = option(
        None,
        group=MODEL_MODE,
        help=(
            "operating threshold of the set metrics (default: the checkpoint's stored "
            "operating_threshold, else its decode threshold); mAP always uses every decoded box"
        ),
    )
    baselines: bool = option(
        True,
        negatable=True,
        group=MODEL_MODE,
        help="also score the language-blind oracle and the class-noun prompt (default: on)",
    )
    radar_folder: str = option(
        "auto", group=MODEL_MODE, help="radar tree to read: auto, none or a folder name"
    )
    scene_labels: Path | None = option(
        None,
        group=MODEL_MODE,
        help="the View-of-Delft root whose label_2 lists every object of the frames (the "
        "language-blind oracle's objects; with it nothing under the root's meta/ is read)",
    )
    candidates: CandidateSource = option(
        "detector",
        group=MODEL_MODE,
        help="what the referent stage chooses among: the detector's proposals (default) or the "
        "frame's labelled boxes from --scene-labels (grounding apart from detection)",
    )
    device: str = option("cpu", group=MODEL_MODE, help="cpu or cuda")
    workers: int = option(
        0,
        group=MODEL_MODE,
        help="processes that predict, this one and N-1 workers, each with one torch thread "
        "(default 0: the usable cores, one per 40 distinct frames at most, 1 on cuda; 1: this "
        "process alone, torch's threads as set)",
    )
    worker_timeout: float = option(
        20.0,
        group=MODEL_MODE,
        help="seconds a prediction worker may take for a frame at least (default 20; more when "
        "this process measures frames slower: 20x its time per frame; a worker's start may take "
        "3x this); a worker past it, or one that dies, ends the run with one line",
    )
    limit: int = option(0, group=MODEL_MODE, help="first N frames only (0: all)")
    json: Path | None = option(None, help="write the results as JSON here")
    exact_overlaps: bool = option(
        False,
        help=(
            "score the boxes exactly as written; by default, like the official devkit, detections "
            "are rotated by +0.01 rad and their 2D boxes shifted by +0.01 px before overlaps"
        ),
    )

    def mode(self) -> Literal["files", "model"]:
        """Which of the two modes the flags ask for.

        Raises:
            ValueError: neither mode, or flags of both, or ``--labels`` without ``--preds`` (or
                the reverse); the message is the command line's error.
        """
        if self.data is not None:
            if self.labels is not None or self.preds is not None:
                raise ValueError("--data does not go with --labels/--preds")
            if self.classes != "vod":
                raise ValueError(
                    "--classes goes with --labels/--preds; --data scores the checkpoint's class set"
                )
            from scenes.datasets.source import root_family

            if self.talk2car is None:  # a nuScenes root needs its commands (RootError: ValueError)
                root_family(self.data, None, commands_required=True)
            return "model"
        if self.talk2car is not None:
            raise ValueError("--talk2car goes with --data NUSC (a nuScenes root)")
        if self.labels is None and self.preds is None:
            raise ValueError(
                "give --labels DIR --preds DIR, or --data ROOT [--checkpoint PATH] [--out DIR]"
            )
        if self.labels is None or self.preds is None:
            raise ValueError("--labels and --preds go together")
        return "files"


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m model.evaluate``: :class:`EvaluateConfig`'s flags."""
    return command_parser(
        "python -m model.evaluate",
        "Official View-of-Delft evaluation (3D / BEV AP and AOS per class, entire annotated area "
        "and driving corridor, 11-point AP with 40-point AP beside it).",
        EvaluateConfig,
    )


def parse_args(argv: Sequence[str] | None = None) -> EvaluateConfig:
    """The :class:`EvaluateConfig` of a command line (a mode error exits 2 with usage, as
    argparse's own errors)."""
    parser = build_parser()
    cfg = from_args(EvaluateConfig, parser.parse_args(argv))
    try:
        cfg.mode()
    except ValueError as exc:
        parser.error(str(exc))
    return cfg


def _run_files_mode(cfg: EvaluateConfig) -> int:
    scored = score_directories(
        cfg.labels, cfg.preds, not cfg.exact_overlaps, class_set(cfg.classes)
    )
    print(
        f"labels: {cfg.labels} ({len(scored.frame_ids)} frames); predictions: {cfg.preds}"
        + (
            f" ({len(scored.missing_predictions)} files missing, scored as no detections)"
            if scored.missing_predictions
            else ""
        )
    )
    print(scored.result.format_table(), end="")
    note = scored.result.unknown_classes_note()
    if note is not None:
        print(f"warning: {note}", file=sys.stderr)
    if cfg.json is not None:
        write_json(cfg.json, scored.result)
        print(f"wrote {cfg.json}")
    return 0


def default_out_dir(data: Path, split: str) -> Path:
    """Where model mode writes its prediction files without ``--out``:
    ``runs/eval/<root folder name>-<split>``."""
    return DEFAULT_EVAL_DIR / f"{data.resolve().name}-{split}"


def evaluation_kind(cfg: EvaluateConfig) -> EvaluationKind:
    """Model mode's plug-in of :func:`model.evaluation.pipeline.run_evaluation` for the root's
    kind: a nuScenes root's Talk2Car commands (``--talk2car``) or a Talk2Radar root, with the
    command line's settings and output paths (without ``--out``: :func:`default_out_dir`, and for a
    Talk2Radar root the JSON beside it as ``<that folder>.json`` unless ``--json`` is given)."""
    out = cfg.out or default_out_dir(cfg.data, cfg.split)
    shared = ("data", "split", "checkpoint", "threshold", "device", "limit")
    common = {"out": out, **_fields(cfg, *shared)}
    if cfg.talk2car is not None:
        from model.evaluation.talk2car.kind import Talk2CarEvaluation

        return Talk2CarEvaluation(talk2car=cfg.talk2car, json=cfg.json, **common)
    from model.evaluation.talk2radar import Talk2RadarEvaluation

    json_path = cfg.json
    if cfg.out is None and json_path is None:
        json_path = out.with_name(out.name + ".json")
    own = _fields(cfg, "baselines", "radar_folder", "scene_labels", "candidates", "workers")
    return Talk2RadarEvaluation(json=json_path, worker_timeout=cfg.worker_timeout, **own, **common)


def _fields(cfg: EvaluateConfig, *names: str) -> dict[str, object]:
    """``{name: cfg.name}`` for ``names``: the settings an evaluation kind takes as they are."""
    return {name: getattr(cfg, name) for name in names}


def _run_model_mode(cfg: EvaluateConfig) -> int:
    """Ground the split with the checkpoint, write and score its predictions, print the tables
    (:mod:`model.evaluation.pipeline`, with :func:`evaluation_kind`'s plug-in)."""
    run_evaluation(evaluation_kind(cfg))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    cfg = parse_args(argv)
    runner = _run_model_mode if cfg.mode() == "model" else _run_files_mode
    return report_errors(lambda: runner(cfg), (ValueError, PredictionWorkerError, OSError))


if __name__ == "__main__":
    sys.exit(main())
