"""The one pipeline of ``python -m model.evaluate --data ROOT``, whichever dataset the root holds:
prepare (settings checked, checkpoint loaded, root opened) -> predict -> score -> write the
predictions -> print -> the report's JSON (:func:`run_evaluation`).

What differs between the datasets is a plug-in, an :class:`EvaluationKind` chosen by the root's
kind (``model.evaluate``): :class:`model.evaluation.talk2radar.Talk2RadarEvaluation` (the VoD
metric and the grounding tables, one KITTI file per frame) and
:class:`model.evaluation.talk2car.kind.Talk2CarEvaluation` (table II, one JSON predictions file).
A new dataset is one more such class.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Protocol


class Report(Protocol):
    """A kind's figures: printed, and written as JSON."""

    def format_tables(self) -> str:
        """The printed tables (ending with a newline)."""
        ...

    def to_dict(self) -> dict:
        """JSON-ready figures."""
        ...


class EvaluationKind(Protocol):
    """The stages of :func:`run_evaluation` for one kind of root. ``run`` is what :meth:`prepare`
    opened (the kind's own type); ``json`` is where the report goes (None: nowhere)."""

    json: Path | None

    def prepare(self) -> Any:
        """Check the settings, load the checkpoint, open the root (errors before any work)."""
        ...

    def predict(self, run: Any) -> Iterable[Any]:
        """The predictions, in the root's order (may be lazy: :meth:`score` takes them as they
        come)."""
        ...

    def score(self, run: Any, predictions: Iterable[Any]) -> Report:
        """The figures of the predictions."""
        ...

    def write(self, run: Any, report: Report) -> tuple[Report, Path]:
        """Write the prediction file(s); the report to print (scored again from the files where
        the kind does so) and the path written."""
        ...

    def heading(self, run: Any, report: Report, written: Path) -> list[str]:
        """The lines printed before the report's tables."""
        ...

    def closing(self, run: Any, report: Report, written: Path) -> list[str]:
        """The lines printed after them."""
        ...


def write_json(path: str | Path, result: Any) -> None:
    """Write the result's ``to_dict()`` as indented JSON (parent folders created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result.to_dict(), indent=2) + "\n")


def run_evaluation(kind: EvaluationKind) -> Report:
    """Prepare, predict, score, write and print one evaluation; the report's JSON written to
    ``kind.json`` where given. Returns the report."""
    run = kind.prepare()
    report = kind.score(run, kind.predict(run))
    report, written = kind.write(run, report)
    for line in kind.heading(run, report, written):
        print(line)
    print(report.format_tables(), end="")
    for line in kind.closing(run, report, written):
        print(line)
    if kind.json is not None:
        write_json(kind.json, report)
        print(f"wrote {kind.json}")
    return report
