"""Choose a checkpoint's operating threshold on a validation split and store it in the checkpoint.

``python -m model.calibrate --data ROOT --checkpoint PATH [--split val] [--limit N] [--dry-run]
[--min-prompts N]``

The operating threshold is the score above which a model's boxes are its answer: the set the app
shows and the set metrics of :mod:`model.evaluation.grounding` score. It is chosen, never tuned on the
test split, as the highest threshold in :data:`CANDIDATES` whose mean per-prompt set F1 on the
validation prompts is within :data:`F1_PLATEAU` points of the best, and written into
the checkpoint's metadata as ``operating_threshold`` with ``operating_threshold_source`` (root,
split, prompts, the F1 and exact-set it reached). :func:`model.evaluation.predict.operating_threshold` reads it
back for ``model.evaluate`` and the app. Both paths (referent and the paper's) are calibrated the
same way, so their set metrics compare fairly.

A split that cannot measure a threshold is refused (exit 2, one line, the checkpoint untouched):
one whose prompts refer to nothing (every threshold that returns nothing would score a perfect set
F1 there) or with fewer than :data:`MIN_REFERRED_PROMPTS` prompts that refer to something.
Every bad input (a malformed label, prompt or calibration file of the split, a checkpoint that
cannot be read) is one line too, ``error: ...``, exit 2.

At the end of a referent-path training run (:func:`calibrate_run`) a calibration that fails is a
warning, never the run's failure: the checkpoint is written, ``python -m model.train`` exits 0,
and the warning says why and which command calibrates the run later.
"""

from __future__ import annotations

import argparse
import contextlib
import shlex
import sys
import traceback
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from model.evaluation.grounding import PromptBoxes, prompt_outcome
from model.evaluation.predict import iterate_predictions
from scenes.utils.cli import command_parser, error_line, option, run_command
from scenes.utils.run_lock import RunLockError, run_lock

if TYPE_CHECKING:
    from model.tpcnet import TPCNet

CANDIDATES: tuple[float, ...] = tuple(round(float(t), 3) for t in np.arange(0.05, 0.951, 0.025))
"""Thresholds tried."""

F1_PLATEAU = 0.5
"""Set-F1 points (of 100) within which thresholds count as equally good; the highest of them is
chosen. On a few hundred validation prompts such differences are noise (one prompt's F1 moves the
mean by 0.4 points on 240), and of equally good thresholds the highest returns the fewest false
boxes: what matters where a scene holds clutter the training data did not (real frames). The
referent checkpoint's curve is flat from 0.15 to 0.65 (set F1 83-84); this picks 0.4 there, with
a higher exact-set rate than the argmax 0.2."""


MIN_REFERRED_PROMPTS = 50
"""Prompts with at least one referent a calibration split must hold (``--min-prompts``). Below
it one prompt moves the mean set F1 by more than 2 points, four times :data:`F1_PLATEAU`, and the
choice is noise."""


class CalibrationError(ValueError):
    """The split cannot measure an operating threshold; the message says why."""


@dataclass(frozen=True)
class Calibration:
    """The chosen threshold and what it reached on the calibration prompts."""

    threshold: float
    set_f1: float
    exact_set: float
    prompts: int
    curve: tuple[tuple[float, float, float], ...]
    """``(threshold, mean set F1 %, exact-set %)`` for every candidate."""


def choose_threshold(
    answers: Sequence[tuple[PromptBoxes, PromptBoxes]],
    candidates: Sequence[float] = CANDIDATES,
) -> Calibration:
    """The highest threshold whose mean set F1 over ``(predicted, referents)`` pairs is within
    :data:`F1_PLATEAU` of the best (module doc).

    Raises:
        ValueError: No prompts.
    """
    if not answers:
        raise ValueError("no prompts to calibrate on")
    curve = []
    for t in candidates:
        outs = [prompt_outcome("", (), p, r, t) for p, r in answers]
        curve.append(
            (
                float(t),
                100.0 * np.mean([o.f1 for o in outs]),
                100.0 * np.mean([o.exact for o in outs]),
            )
        )
    top = max(c[1] for c in curve)
    best = max((c for c in curve if c[1] >= top - F1_PLATEAU - 1e-9), key=lambda c: c[0])
    return Calibration(best[0], best[1], best[2], len(answers), tuple(curve))


def calibrate(
    model: TPCNet,
    data: str | Path,
    split: str = "val",
    limit: int = 0,
    min_prompts: int = MIN_REFERRED_PROMPTS,
    talk2car: str | Path | None = None,
) -> Calibration:
    """Ground every prompt of ``split`` with ``model`` (a loaded checkpoint) and choose its
    threshold; ``talk2car``: ``data`` is a nuScenes root and these are its command files (each
    command one prompt with its one referent, :func:`talk2car_answers`).

    Raises:
        CalibrationError: fewer than ``min_prompts`` (and at least one) of the prompts have a
            referent (module docstring).
    """
    from model.evaluation.predict import decode_threshold
    from scenes.datasets.family_files import split_list_file
    from scenes.datasets.source import open_source

    low = min(decode_threshold(model), CANDIDATES[0])
    if talk2car is not None:
        answers = talk2car_answers(model, data, talk2car, split, limit, low)
        where = f"{Path(talk2car) / f'{split}_commands.json'}"
    else:
        root = open_source(data, classes=model.cfg.class_set)  # a Talk2Radar root
        ids = root.ids(split)[: limit or None]
        answers = []
        for fp in iterate_predictions(model, root, ids, score_threshold=low):
            source = fp.sample.sample_id
            predicted = PromptBoxes.make(fp.boxes, fp.classes, fp.scores, source=source)
            referents = PromptBoxes.make(fp.sample.boxes, fp.sample.classes)
            answers.append((predicted, referents))
        where = str(split_list_file(root, split))
    referred = sum(len(r.boxes) > 0 for _, r in answers)
    if referred < max(1, min_prompts):
        raise CalibrationError(
            f"{where}: {referred} of the "
            f"{len(answers)} prompts of split {split!r} have a referent; calibrating needs at "
            f"least {max(1, min_prompts)} (--min-prompts), so no threshold is chosen"
        )
    return choose_threshold(answers)


def talk2car_answers(
    model: TPCNet,
    data: str | Path,
    talk2car: str | Path,
    split: str,
    limit: int,
    score_threshold: float,
) -> list[tuple[PromptBoxes, PromptBoxes]]:
    """``(answer, referent)`` of each command of a nuScenes root's ``split`` with a referent in
    the class set (:func:`model.evaluation.talk2car.predict.iterate_command_predictions`)."""
    from model.evaluation.talk2car.predict import iterate_command_predictions
    from scenes.datasets.family_files import nuscenes_class_mapping
    from scenes.datasets.nuscenes_frames import open_talk2car

    root, commands = open_talk2car(data, talk2car, split, model.cfg.class_set)
    answers = []
    for p in iterate_command_predictions(
        model,
        root,
        commands,
        nuscenes_class_mapping(model.cfg.class_set),  # the model's class set
        score_threshold,
        progress=False,
        limit=limit,
    ):
        a = p.answer
        source = p.command.command_token
        predicted = PromptBoxes.make(a.boxes, a.classes, a.scores, source=source)
        answers.append((predicted, PromptBoxes.make(a.referent[None], [a.referent_class])))
    return answers


def calibrate_file(
    path: str | Path,
    data: str | Path,
    split: str = "val",
    limit: int = 0,
    min_prompts: int = MIN_REFERRED_PROMPTS,
    dry_run: bool = False,
    talk2car: str | Path | None = None,
) -> Calibration:
    """Calibrate the checkpoint at ``path`` on ``split`` of ``data`` and, unless ``dry_run``,
    store the threshold and its source in it (``python -m model.calibrate``; training calls it at
    the end of a referent-path run).

    Raises:
        CalibrationError: the split cannot measure a threshold (the checkpoint is untouched).
    """
    from model.checkpoint import load_checkpoint, save_checkpoint
    from model.checkpoint_meta import CheckpointMeta, portable_path

    model = load_checkpoint(path)
    cal = calibrate(model, data, split, limit, min_prompts, talk2car)
    if not dry_run:
        meta = CheckpointMeta.of(model).replace(
            operating_threshold=cal.threshold,
            operating_threshold_source={
                "root": portable_path(data),
                "split": split,
                "prompts": cal.prompts,
                "set_f1": round(cal.set_f1, 2),
                "exact_set": round(cal.exact_set, 2),
            },
        )
        save_checkpoint(path, model, **meta.to_dict())
    return cal


def calibrate_run(
    path: Path, data: str | Path, split: str, talk2car: str | Path | None = None
) -> bool:
    """Calibrate a finished training run's ``last.pt`` (``path``) on ``split`` of ``data`` (a
    nuScenes root's commands with ``talk2car``); whether the threshold was stored.

    The run is finished and its checkpoint written whatever happens here, so nothing here fails
    it: a split that cannot measure a threshold, a malformed file of the split (a label, a
    prompt, a calibration file), a missing package or a fault of the code leave the checkpoint
    at the uncalibrated threshold, with one ``warning:`` line on stderr saying why and the
    command that calibrates it later (a fault of the code also prints its traceback above);
    ``python -m model.train`` exits 0.
    """
    try:
        cal = calibrate_file(path, data, split, talk2car=talk2car)
    except (ValueError, OSError, ImportError) as exc:  # bad input: one line, as everywhere
        reason = error_line(exc)
    except Exception as exc:  # a bug, not the data: its traceback, and still a warning
        traceback.print_exc()
        reason = f"{type(exc).__name__}: {error_line(exc)}"
    else:
        print(
            f"operating threshold {cal.threshold:.3f} (set F1 {cal.set_f1:.1f} on {cal.prompts} "
            f"{split} prompts) stored in {path}"
        )
        return True
    later = shlex.join(
        [
            "python",
            "-m",
            "model.calibrate",
            "--data",
            str(data),
            "--checkpoint",
            str(path),
            "--split",
            split,
            *(["--talk2car", str(talk2car)] if talk2car is not None else []),
        ]
    )
    print(
        f"warning: training finished and {path} is written, but not calibrated (its operating "
        f"threshold stays the uncalibrated one): {reason}; calibrate it later: {later}",
        file=sys.stderr,
    )
    return False


@dataclass(frozen=True, kw_only=True)
class CalibrateConfig:
    """The settings of ``python -m model.calibrate`` (each field is one of its flags)."""

    data: str = option(help="Talk2Radar root with a validation split, or a nuScenes root")
    talk2car: str | None = option(
        None, help="the nuScenes --data root's Talk2Car command folder ({split}_commands.json)"
    )
    checkpoint: str = option(help="checkpoint to calibrate (rewritten)")
    split: str = option("val")
    limit: int = option(0, help="first N samples only (0: all)")
    dry_run: bool = option(False, help="print the choice, write nothing")
    min_prompts: int = option(
        MIN_REFERRED_PROMPTS,
        help=f"prompts with a referent the split must hold (default {MIN_REFERRED_PROMPTS})",
    )


def build_parser() -> argparse.ArgumentParser:
    """``python -m model.calibrate``'s parser (:class:`CalibrateConfig`'s flags)."""
    return command_parser("python -m model.calibrate", __doc__.split("\n")[0], CalibrateConfig)


def run(a: CalibrateConfig) -> int:
    """Calibrate as ``a`` says and print the curve and the choice (errors raise). The folder of
    the checkpoint rewritten is locked meanwhile (:mod:`scenes.utils.run_lock`: a training run
    or another calibration writing there refuses this one; not for ``--dry-run``)."""
    with contextlib.ExitStack() as held:
        if not a.dry_run:
            held.enter_context(run_lock(Path(a.checkpoint).parent, "--checkpoint"))
        cal = calibrate_file(
            a.checkpoint,
            a.data,
            a.split,
            a.limit,
            a.min_prompts,
            dry_run=a.dry_run,
            talk2car=a.talk2car,
        )
    for t, f1, exact in cal.curve:
        mark = "  <- chosen" if t == cal.threshold else ""
        print(f"threshold {t:.3f}: set F1 {f1:5.1f}  exact-set {exact:5.1f}{mark}")
    print(
        f"operating threshold {cal.threshold:.3f} (set F1 {cal.set_f1:.1f}, exact-set "
        f"{cal.exact_set:.1f} on {cal.prompts} prompts of {a.data} {a.split})"
    )
    if not a.dry_run:
        print(f"wrote operating_threshold into {a.checkpoint}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m model.calibrate``; a bad checkpoint or root (CheckpointError, RootError: both
    ValueErrors) is one ``error:`` line, exit status 2."""
    return run_command(
        build_parser(), CalibrateConfig, run, argv, (ValueError, OSError, ImportError, RunLockError)
    )


if __name__ == "__main__":
    sys.exit(main())
