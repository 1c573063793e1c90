"""A report's JSON file (model/evaluation/report_file.py): what ``GroundingReport.to_dict``
writes, ``ReportFile.read`` reads back, figure for figure, and the tables print it."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import replace

import numpy as np
import pytest

from model.evaluation.grounding import (
    GroundingSummary,
    PromptBoxes,
    grounding_metrics,
    prompt_outcome,
)
from model.evaluation.report import ROW_NAMES, BaselineResult, build_report
from model.evaluation.report_file import ReportFile, ReportFileError, SummaryFigures
from model.evaluation.results_table import Row, by_depth_table, grounding_table, overall_table
from scenes.frame.kitti import ObjectLabel
from tests.paths import REPO


def _car(z: float, score: float | None = None) -> ObjectLabel:
    return ObjectLabel(
        name="Car",
        truncated=0.0 if score is None else -1.0,
        occluded=0 if score is None else -1,
        alpha=0.2,
        bbox=(500.0, 400.0, 580.0, 500.0),
        dimensions_hwl=(1.5, 1.8, 4.0),
        location=(0.0, 1.5, z),
        rotation_y=0.1 if score is None else 0.11,
        score=score,
    )


def _report():
    """Six frames with one car each at 8..33 m, five found; prompts of two types; a model and
    an oracle answer set."""
    ids = [f"{i:05d}" for i in range(6)]
    gt = {f: [_car(8.0 + 5 * i)] for i, f in enumerate(ids)}
    dt = {f: [replace(gt[f][0], score=0.9 - 0.1 * i)] for i, f in enumerate(ids[:5])}
    tags = {f: frozenset({"depth"} if i % 2 else {"motion", "position"}) for i, f in enumerate(ids)}
    box = np.array([[10.0, 0.0, 0.0, 4.0, 1.8, 1.5, 0.0]])
    far = box.copy()
    far[0, 0] += 3.0  # 3 m off: a miss
    outcomes = [
        prompt_outcome(
            f,
            tags[f],
            PromptBoxes.make(box if i < 4 else far, ["Car"], [0.8 - 0.1 * i]),
            PromptBoxes.make(box, ["Car"]),
            0.5,
        )
        for i, f in enumerate(ids)
    ]
    report = build_report(gt, dt, tags, seconds=(0.1, 0.2))
    oracle = BaselineResult(build_report(gt, gt, tags).result, grounding_metrics(outcomes, 1.0))
    return replace(report, grounding=grounding_metrics(outcomes, 0.5), baselines={"oracle": oracle})


def test_what_the_report_writes_reads_back_figure_for_figure() -> None:
    report = _report()
    read = ReportFile.read(json.loads(json.dumps(report.to_dict())), "r.json", "m", ROW_NAMES)
    assert read.num_frames == 6
    for name in ("entire_area", "roi"):
        area, back = report.result.area(name), read.areas[name]
        assert back is not None
        assert back.ap_3d == {c.name: c.ap_3d.r11 for c in area.classes}
        assert (back.map_3d, back.maos, back.map_3d_r40) == (
            area.map_3d,
            area.maos,
            area.map_3d_r40,
        )
    assert read.by_type is not None and read.by_depth is not None
    assert {k: (v.count, v.entire_area.map_3d) for k, v in read.by_type.items()} == {
        k: (n, r.entire_area.map_3d) for k, (n, r) in report.by_type.items()
    }
    assert {k: (v.count, v.entire_area.map_3d) for k, v in read.by_depth.items()} == {
        k: (n, r.entire_area.map_3d) for k, (n, r) in report.by_depth.items()
    }
    assert read.answer_sets is not None
    assert [a.label for a in read.answer_sets] == ["m", "m oracle"]
    written = [
        (report.grounding, report.result),
        *[(b.grounding, b.result) for b in report.baselines.values()],
    ]
    for back, (metrics, result) in zip(read.answer_sets, written, strict=True):
        assert back.threshold == metrics.threshold
        assert back.entire_area.map_3d == result.entire_area.map_3d
        for mine, theirs in [
            (back.overall, metrics.overall),
            *[(back.by_type[k], v) for k, v in metrics.by_type.items()],
            *[(back.by_group[k], v) for k, v in metrics.by_group.items()],
        ]:
            assert dataclasses.asdict(mine) == {
                f.name: getattr(theirs, f.name) for f in dataclasses.fields(SummaryFigures)
            }
        assert set(back.by_type) == set(metrics.by_type)
        assert set(back.by_group) == set(metrics.by_group)
    # the tables print the report's own figures
    row = Row("m", read)
    assert f"**{report.result.entire_area.map_3d:.2f}**" in overall_table([row])
    assert "| m oracle | 6 |" in grounding_table([row])
    assert by_depth_table([row]).splitlines()[0].startswith("| model | 0-10 m |")


def test_a_summary_is_written_with_the_keys_and_order_of_the_shipped_files() -> None:
    shipped = json.loads((REPO / "docs" / "results" / "referent-eval-s99.json").read_text())
    written = _report().to_dict()
    assert list(written["grounding"]["overall"]) == list(shipped["grounding"]["overall"])
    assert list(written["entire_area"]) == list(shipped["entire_area"])
    assert issubclass(GroundingSummary, SummaryFigures)  # the figures the tables read


def test_a_missing_field_is_named_with_its_place() -> None:
    data = _report().to_dict()
    del data["baselines"]["oracle"]["grounding"]["by_group"]["single"]["exact"]
    with pytest.raises(
        ReportFileError, match=r"r.json \[m oracle\] grounding \[single\]: .*'exact'"
    ):
        ReportFile.read(json.loads(json.dumps(data)), "r.json", "m", ROW_NAMES)
    data = _report().to_dict()
    del data["by_depth"]
    read = ReportFile.read(data, "r.json", "m", ROW_NAMES)
    with pytest.raises(ReportFileError, match=r"r.json: missing field 'by_depth'"):
        by_depth_table([Row("m", read)])
