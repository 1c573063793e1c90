"""Command line for the official View-of-Delft evaluation (:mod:`model.metrics`).

``python -m model.evaluate --labels DIR --preds DIR [--json OUT]`` scores KITTI-format prediction
files (``<frame id>.txt``, one detection per line with a 16th score field) against label files.

Decisions (the devkit behaves differently, see the spec §2.2):

- The frame list comes from the LABEL folder (every ``*.txt`` in it, not recursive). A frame whose
  prediction file is missing counts as a frame with no detections, so its ground truth counts as
  missed; the devkit would drop the frame instead and inflate AP.
- A prediction file for a frame with no label file is an error naming the file(s): it almost always
  means the wrong label folder or split.
- Overlaps follow the devkit, including its +0.01 rad / +0.01 px offsets on detections
  (``--exact-overlaps`` turns them off; see :mod:`model.metrics`).
- A malformed prediction line is an error naming the file and line. Within one prediction file the
  lines must either all carry a score or none (then every score is 0, the devkit's rule).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from model.metrics import VodResult, evaluate_frames

if TYPE_CHECKING:
    from model.report import GroundingReport
from scenes.kitti import LabelError, ObjectLabel, parse_label_line, read_label_file


class EvaluationInputError(ValueError):
    """Label or prediction folders that cannot be scored; the message names the files."""


@dataclass(frozen=True)
class ScoredDirectories:
    """The result of scoring a prediction folder.

    Attributes:
        result: The metric.
        frame_ids: Frames evaluated (from the label folder), sorted.
        missing_predictions: Frames with no prediction file (scored as no detections).
    """

    result: VodResult
    frame_ids: tuple[str, ...]
    missing_predictions: tuple[str, ...]


def _txt_files(folder: Path, what: str) -> dict[str, Path]:
    if not folder.is_dir():
        raise EvaluationInputError(f"{what} folder {folder} does not exist or is not a folder")
    return {
        p.stem: p
        for p in sorted(folder.glob("*.txt"))
        if p.is_file() and not p.name.startswith(".")
    }


def load_label_dir(folder: str | Path) -> dict[str, list[ObjectLabel]]:
    """Every ``<frame id>.txt`` label file of ``folder`` -> frame id -> labels.

    Raises:
        EvaluationInputError: the folder is missing or holds no ``.txt`` files.
        scenes.kitti.LabelError: a malformed line (file and line named).
    """
    folder = Path(folder)
    files = _txt_files(folder, "label")
    if not files:
        raise EvaluationInputError(f"label folder {folder} holds no .txt label files")
    return {frame: read_label_file(path) for frame, path in files.items()}


def read_prediction_file(path: str | Path) -> list[ObjectLabel]:
    """Read one prediction file (empty file -> no detections); errors name the file and line.

    Raises:
        scenes.kitti.LabelError: a malformed line, or a file mixing lines with and without score.
    """
    path = Path(path)
    labels: list[ObjectLabel] = []
    for lineno, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        label = parse_label_line(line, source=f"{path}:{lineno}")
        if labels and (label.score is None) != (labels[0].score is None):
            raise LabelError(
                f"{path}:{lineno}: prediction lines must all have a score (16 fields) or none; "
                f"the first line {'lacks' if labels[0].score is None else 'has'} one and this "
                f"one does not: {line.strip()!r}"
            )
        labels.append(label)
    return labels


def load_prediction_dir(
    folder: str | Path, frame_ids: Sequence[str]
) -> tuple[dict[str, list[ObjectLabel]], tuple[str, ...]]:
    """Predictions of ``frame_ids`` from ``folder``.

    Returns:
        ``(frame id -> detections, frames whose file is missing)``; missing files give no
        detections.

    Raises:
        EvaluationInputError: ``folder`` is missing, or holds files for frames not in ``frame_ids``.
        scenes.kitti.LabelError: a malformed prediction line (file and line named).
    """
    folder = Path(folder)
    files = _txt_files(folder, "prediction")
    known = set(frame_ids)
    extra = sorted(set(files) - known)
    if extra:
        shown = ", ".join(str(files[f]) for f in extra[:5])
        more = f" and {len(extra) - 5} more" if len(extra) > 5 else ""
        raise EvaluationInputError(
            f"{len(extra)} prediction file(s) have no label file: {shown}{more} "
            "(wrong label folder or split?)"
        )
    preds = {f: read_prediction_file(files[f]) for f in frame_ids if f in files}
    missing = tuple(f for f in frame_ids if f not in files)
    return preds, missing


def score_directories(
    labels: str | Path, preds: str | Path, devkit_offsets: bool = True
) -> ScoredDirectories:
    """Score the prediction folder ``preds`` against the label folder ``labels``
    (``devkit_offsets``: see :func:`model.metrics.evaluate_frames`)."""
    gt = load_label_dir(labels)
    frame_ids = tuple(sorted(gt))
    dt, missing = load_prediction_dir(preds, frame_ids)
    return ScoredDirectories(
        result=evaluate_frames(gt, dt, devkit_offsets=devkit_offsets),
        frame_ids=frame_ids,
        missing_predictions=missing,
    )


def write_json(path: str | Path, result: VodResult | GroundingReport) -> None:
    """Write the result's ``to_dict()`` as indented JSON (parent folders created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result.to_dict(), indent=2) + "\n")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m model.evaluate",
        description=(
            "Official View-of-Delft evaluation (3D / BEV AP and AOS per class, entire annotated "
            "area and driving corridor, 11-point AP with 40-point AP beside it)."
        ),
    )
    files = parser.add_argument_group("score prediction files")
    files.add_argument("--labels", type=Path, help="folder of ground-truth label_2 files")
    files.add_argument(
        "--preds",
        type=Path,
        help="folder of prediction files <frame id>.txt (a missing file = no detections)",
    )
    model_mode = parser.add_argument_group("ground a split with a checkpoint, then score it")
    model_mode.add_argument("--data", type=Path, help="Talk2Radar root")
    model_mode.add_argument("--split", default="test", help="ImageSets split (default: test)")
    model_mode.add_argument("--checkpoint", type=Path, help="model checkpoint (.pt)")
    model_mode.add_argument("--out", type=Path, help="folder for the prediction files")
    model_mode.add_argument(
        "--radar-folder", default="auto", help="radar tree to read: auto, none or a folder name"
    )
    model_mode.add_argument("--device", default="cpu", help="cpu or cuda")
    model_mode.add_argument("--limit", type=int, default=0, help="first N frames only (0: all)")
    parser.add_argument("--json", type=Path, default=None, help="write the results as JSON here")
    parser.add_argument(
        "--exact-overlaps",
        action="store_true",
        help=(
            "score the boxes exactly as written; by default, like the official devkit, detections "
            "are rotated by +0.01 rad and their 2D boxes shifted by +0.01 px before overlaps"
        ),
    )
    return parser


def _run_files_mode(args: argparse.Namespace) -> int:
    scored = score_directories(args.labels, args.preds, devkit_offsets=not args.exact_overlaps)
    print(
        f"labels: {args.labels} ({len(scored.frame_ids)} frames); predictions: {args.preds}"
        + (
            f" ({len(scored.missing_predictions)} files missing, scored as no detections)"
            if scored.missing_predictions
            else ""
        )
    )
    print(scored.result.format_table(), end="")
    if args.json is not None:
        write_json(args.json, scored.result)
        print(f"wrote {args.json}")
    return 0


def _run_model_mode(args: argparse.Namespace) -> int:
    """Ground every sample of a split, write one prediction file per frame, score them, and print
    the official table plus the per-prompt-type and per-depth tables."""
    from model.checkpoint import load_checkpoint
    from model.predict import write_predictions
    from model.report import evaluate_predictions
    from scenes.root import Talk2RadarRoot

    radar = None if args.radar_folder == "none" else args.radar_folder
    root = Talk2RadarRoot(args.data, radar=radar)
    ids = root.ids(args.split)
    if args.limit:
        ids = ids[: args.limit]
    if not ids:
        raise EvaluationInputError(f"{args.data}: split {args.split!r} has no samples")
    model = load_checkpoint(args.checkpoint, device=args.device)
    report = evaluate_predictions(model, root, ids)
    out = write_predictions(report.predictions, args.out)
    # Score the files as written (4 decimals), as the official devkit reads them.
    from_files, missing = load_prediction_dir(out, tuple(sorted(ids)))
    if missing:
        raise EvaluationInputError(f"{out}: prediction files missing for {list(missing)[:5]}")
    report = report.rescored(from_files)
    print(f"data: {args.data} split {args.split} ({len(ids)} frames); checkpoint {args.checkpoint}")
    print(f"predictions written to {out}")
    print(report.format_tables(), end="")
    if args.json is not None:
        write_json(args.json, report)
        print(f"wrote {args.json}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.data is not None:
        if args.labels is not None or args.preds is not None:
            parser.error("--data does not go with --labels/--preds")
        if args.checkpoint is None or args.out is None:
            parser.error("--data needs --checkpoint PATH and --out DIR")
        runner = _run_model_mode
    elif args.labels is None and args.preds is None:
        parser.error("give --labels DIR --preds DIR, or --data ROOT --checkpoint PATH --out DIR")
    elif args.labels is None or args.preds is None:
        parser.error("--labels and --preds go together")
    else:
        runner = _run_files_mode
    try:
        return runner(args)
    except (EvaluationInputError, LabelError, ValueError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
