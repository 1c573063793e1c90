"""The Talk2Car kind of ``python -m model.evaluate --data NUSC --talk2car CMDS``
(:mod:`model.evaluation.pipeline`'s stages): a nuScenes root's commands of a split grounded
(:mod:`model.evaluation.talk2car.predict`), scored into table II
(:mod:`model.evaluation.talk2car.report`), and written as ``OUT/{split}_predictions.json`` in the
command file's CAM_FRONT frame.

The predictions file is Talk2Car's format, so its boxes are turned into the command file's
CAM_FRONT frame by the nuScenes family's one conversion
(:func:`scenes.nuscenes.talk2car.model_box_to_camera`), imported here for the file it writes."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from model.evaluation.files import EvaluationInputError
from model.evaluation.talk2car.predict import (
    CommandPrediction,
    iterate_command_predictions,
    predictions_json,
)
from model.evaluation.talk2car.report import Talk2CarReport, build_report

if TYPE_CHECKING:
    from model.tpcnet import TPCNet


@dataclass(frozen=True)
class Talk2CarRun:
    """What :meth:`Talk2CarEvaluation.prepare` opened: the model, the root, its split's commands
    and the model class of a nuScenes category in the checkpoint's class set."""

    model: TPCNet
    root: Any
    commands: Any
    model_class: Callable[[str, Sequence[str]], str | None]


@dataclass(frozen=True, kw_only=True)
class Talk2CarEvaluation:
    """``python -m model.evaluate --data NUSC --talk2car CMDS``: a kind of
    :mod:`model.evaluation.pipeline` (the fields: the command line's settings)."""

    data: Path
    talk2car: Path
    split: str
    checkpoint: Path
    out: Path
    json: Path | None
    threshold: float | None = None
    device: str = "cpu"
    limit: int = 0

    def prepare(self) -> Talk2CarRun:
        """Load the checkpoint, open the root and the split's commands in its class set.

        Raises:
            EvaluationInputError: ``--threshold`` given (AP ranks every box); the loader's and the
                checkpoint's errors.
        """
        from model.checkpoint import load_checkpoint
        from scenes.datasets.family_files import nuscenes_class_mapping
        from scenes.datasets.nuscenes_frames import open_talk2car

        if self.threshold is not None:
            raise EvaluationInputError(
                "--threshold is not used with --talk2car (AP ranks every box)"
            )
        model = load_checkpoint(self.checkpoint, device=self.device)
        root, commands = open_talk2car(self.data, self.talk2car, self.split, model.cfg.class_set)
        classes = nuscenes_class_mapping(model.cfg.class_set)  # the checkpoint's class set
        return Talk2CarRun(model, root, commands, classes)

    def predict(self, run: Talk2CarRun) -> Iterator[CommandPrediction]:
        """Every command with a referent answered, sample by sample (each scene encoded once)."""
        return iterate_command_predictions(
            run.model, run.root, run.commands, run.model_class, limit=self.limit
        )

    def score(self, run: Talk2CarRun, predictions: Iterator[CommandPrediction]) -> Talk2CarReport:
        """Table II's rows.

        Raises:
            ValueError: no command of the split has a referent in the class set.
        """
        kept = list(predictions)
        if not kept:
            raise ValueError(
                f"{Path(self.talk2car) / f'{self.split}_commands.json'}: no command with a "
                "referent in the class set"
            )
        return build_report(kept)

    def write(self, run: Talk2CarRun, report: Talk2CarReport) -> tuple[Talk2CarReport, Path]:
        """``out/{split}_predictions.json`` (:func:`predictions_json`, boxes turned into the command
        file's CAM_FRONT frame by ``scenes.nuscenes.talk2car.model_box_to_camera``)."""
        from scenes.nuscenes.talk2car import model_box_to_camera
        from scenes.utils.durable import atomic_write_text

        self.out.mkdir(parents=True, exist_ok=True)
        path = self.out / f"{self.split}_predictions.json"
        text = json.dumps(predictions_json(report.predictions, model_box_to_camera))
        atomic_write_text(path, text + "\n")
        return report, path

    def heading(self, run: Talk2CarRun, report: Talk2CarReport, written: Path) -> list[str]:
        """The line printed before the table: what was grounded."""
        skipped = sum(run.commands.skipped.values())
        return [
            f"data: {self.data} commands {self.talk2car} split {self.split} "
            f"({len(report.predictions)} commands scored, {skipped} skipped); checkpoint "
            f"{self.checkpoint}"
        ]

    def closing(self, run: Talk2CarRun, report: Talk2CarReport, written: Path) -> list[str]:
        """The line printed after the table: where the predictions went."""
        return [f"predictions written to {written}"]
