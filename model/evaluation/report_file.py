"""The JSON file of a report (``python -m model.evaluate --json``): its shape, in one place.

The writers (:meth:`model.evaluation.results.AreaResult.to_dict`,
:meth:`model.evaluation.grounding.GroundingMetrics.to_dict`,
:meth:`model.evaluation.report.GroundingReport.to_dict` and ``BaselineResult.to_dict``) name
their keys with the constants here, and :meth:`ReportFile.read` reads a file back with the same
constants into typed figures (what :mod:`model.evaluation.results_table` prints)::

    {AREAS[i]: area, ...,                      area = {"<Class>_3d_all": AP, ..., "mAP_3d": ...}
     "num_frames": N,
     "by_prompt_type": {type: {"frames": N, "entire_area": area, "roi": area}},
     "by_depth": {"0-10": {"gt_objects": N, "entire_area": area, "roi": area}, ...},
     "median_seconds_per_frame": s,
     "grounding": grounding,                   grounding = {"operating_threshold": t,
     "baselines": {name: {area..., "grounding": grounding}},    "overall": summary,
     "baseline_notes": {name: why},                              "by_prompt_type": {tag: summary},
     "outside_class_set": outside}                               "by_group": {group: summary}}
                        outside = {"class_set": name, "referents": {label name: N},
                                   "referents_in_scored_prompts": N, "prompts_apart": N,
                                   "prompt_ids_apart": [id, ...]}

A summary holds the fields of :class:`model.evaluation.grounding.GroundingSummary` by name (its
figures are :class:`SummaryFigures`' fields). The figures need only what the tables print (a file may hold more); a section a file lacks (older
files have no ``grounding``) is None, and asking a table for it names the missing field. This
module imports only the protocol's area names, so that the writers can import it.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

from model.evaluation.protocol import AREAS
from scenes.geometry.classes import NUSCENES, VOD

BaselineName = Literal["class_noun", "oracle"]
"""A baseline: the class-noun prompt, the language-blind oracle (JSON keys under ``baselines``)."""

BASELINES: tuple[BaselineName, ...] = typing.get_args(BaselineName)
"""Baseline names, in table order."""

R40 = "_R40"
"""Suffix of a figure at 40 recall points (without it: 11 points)."""

MAP_3D, MAP_BEV, MAOS = "mAP_3d", "mAP_bev", "mAOS"
"""An area's means over the classes."""

NUM_FRAMES, BY_TYPE, BY_DEPTH, FRAMES, GT_OBJECTS = (
    "num_frames",
    "by_prompt_type",
    "by_depth",
    "frames",
    "gt_objects",
)
"""A report's frame count, its per-prompt-type and per-depth-bin results and their counts."""

SECONDS, GROUNDING, BASELINES_KEY, NOTES = (
    "median_seconds_per_frame",
    "grounding",
    "baselines",
    "baseline_notes",
)
"""A report's timing, grounding metrics, baselines and the notes of baselines not computed."""

THRESHOLD, OVERALL, BY_GROUP = "operating_threshold", "overall", "by_group"
"""Grounding metrics' operating threshold, all prompts, per prompt group (per tag: BY_TYPE)."""

OUTSIDE = "outside_class_set"
"""A report's referents outside the model's class set (:mod:`model.evaluation.outside_classes`),
a mapping of the keys below."""

OUTSIDE_CLASS_SET, OUTSIDE_REFERENTS, OUTSIDE_SCORED, OUTSIDE_APART, OUTSIDE_APART_IDS = (
    "class_set",
    "referents",
    "referents_in_scored_prompts",
    "prompts_apart",
    "prompt_ids_apart",
)
"""Under :data:`OUTSIDE`: the model's class set, label name -> referents outside it, those left
in scored prompts (missed), the number of prompts reported apart and their sample ids."""


def class_key(name: str, kind: str, r40: bool = False) -> str:
    """The key of a class's figure: ``kind`` ``3d``, ``bev`` or ``aos``."""
    return f"{name}_{kind}_all" + (R40 if r40 else "")


class ReportFileError(ValueError):
    """A results file that is missing, unreadable or lacks a field (the message names it)."""


def _report_classes(data: object) -> tuple[str, ...]:
    """The class names an area's figures hold: the ``nuscenes`` set's when it has a figure of
    each of them, else the ``vod`` set's (whose missing figure :func:`_num` then names)."""
    if isinstance(data, dict) and all(class_key(c, "3d") in data for c in NUSCENES.names):
        return NUSCENES.names
    return VOD.names


def _field(mapping: object, key: str, where: str) -> object:
    if not isinstance(mapping, Mapping) or key not in mapping:
        raise ReportFileError(f"{where}: missing field {key!r}")
    return mapping[key]


def _num(mapping: object, key: str, where: str) -> float:
    value = _field(mapping, key, where)
    if not isinstance(value, int | float):
        raise ReportFileError(f"{where}: field {key!r} is not a number ({value!r})")
    return float(value)


@dataclass(frozen=True)
class AreaFigures:
    """An area's figures (percent): 3D AP per class and the means, at 11 points unless named."""

    ap_3d: Mapping[str, float]
    map_3d: float
    maos: float
    map_3d_r40: float

    @classmethod
    def read(cls, data: object, where: str) -> AreaFigures:
        return cls(
            {c: _num(data, class_key(c, "3d"), where) for c in _report_classes(data)},
            _num(data, MAP_3D, where),
            _num(data, MAOS, where),
            _num(data, MAP_3D + R40, where),
        )


@dataclass(frozen=True)
class SubsetFigures:
    """A per-prompt-type or per-depth-bin result: its count (frames, or ground-truth objects)
    and its entire-area figures."""

    count: int
    entire_area: AreaFigures


@dataclass(frozen=True)
class SummaryFigures:
    """Grounding figures over a set of prompts (percent, ``prompts`` a count): what the tables
    print of a :class:`model.evaluation.grounding.GroundingSummary`, which adds the totals
    behind them."""

    prompts: int
    acc_25: float
    acc_50: float
    precision: float
    recall: float
    f1: float
    set_f1: float
    exact: float

    @staticmethod
    def read(data: object, where: str) -> SummaryFigures:
        values = {f.name: _num(data, f.name, where) for f in dataclasses.fields(SummaryFigures)}
        return SummaryFigures(**{**values, "prompts": int(values["prompts"])})


@dataclass(frozen=True)
class AnswerSetFigures:
    """What one answer set (the model or a baseline) reached: its grounding metrics and its
    entire-area figures.

    Attributes:
        label: Its row label (the file's name, then the baseline's).
        threshold: The operating threshold of the set metrics.
        overall, by_type, by_group: :class:`SummaryFigures` of all prompts, per tag, per group.
    """

    label: str
    threshold: float
    overall: SummaryFigures
    by_type: Mapping[str, SummaryFigures]
    by_group: Mapping[str, SummaryFigures]
    entire_area: AreaFigures

    @classmethod
    def read(cls, block: object, label: str, where: str) -> AnswerSetFigures:
        g = _field(block, GROUNDING, where)
        w = f"{where} {GROUNDING}"
        parts = {}
        for key in (BY_TYPE, BY_GROUP):
            entries = _field(g, key, w)
            if not isinstance(entries, Mapping):
                raise ReportFileError(f"{w}: field {key!r} is not an object")
            parts[key] = {k: SummaryFigures.read(v, f"{w} [{k}]") for k, v in entries.items()}
        return cls(
            label,
            _num(g, THRESHOLD, w),
            SummaryFigures.read(_field(g, OVERALL, w), f"{w}.{OVERALL}"),
            parts[BY_TYPE],
            parts[BY_GROUP],
            AreaFigures.read(_field(block, AREAS[0], where), where),
        )


def _subsets(data: Mapping, key: str, count: str, source: str) -> dict[str, SubsetFigures] | None:
    """The ``by_prompt_type`` or ``by_depth`` section (None where the file has none)."""
    if key not in data:
        return None
    entries = data[key]
    if not isinstance(entries, Mapping):
        raise ReportFileError(f"{source}: field {key!r} is not an object")
    out = {}
    for name, entry in entries.items():
        where = f"{source} [{key}.{name}]"
        area = AreaFigures.read(_field(entry, AREAS[0], where), where)
        out[name] = SubsetFigures(int(_num(entry, count, where)), area)
    return out


@dataclass(frozen=True)
class ReportFile:
    """A report's JSON file read back (module docstring); a section the file lacks is None.

    Attributes:
        source: The file, as errors name it.
        num_frames: Frames evaluated.
        areas: Area name of :data:`AREAS` -> its figures.
        by_type: Prompt type -> frames of that type and their result.
        by_depth: Depth bin (``"0-10"``, ...) -> ground-truth objects in it and the result.
        answer_sets: The model's grounding (labelled ``name``), then each baseline's present
            (labelled ``name`` and the baseline's row name), in table order; None: no grounding.
    """

    source: str
    num_frames: int | None
    areas: Mapping[str, AreaFigures | None]
    by_type: Mapping[str, SubsetFigures] | None
    by_depth: Mapping[str, SubsetFigures] | None
    answer_sets: tuple[AnswerSetFigures, ...] | None

    @classmethod
    def read(cls, data: object, source: str, name: str, row_names: Mapping[str, str]) -> ReportFile:
        """Read a parsed JSON file; ``name`` labels its answer sets (``row_names``: each
        baseline's row name).

        Raises:
            ReportFileError: not an object, or a section present but lacking a field the tables
                print (file, section and field named).
        """
        if not isinstance(data, Mapping):
            raise ReportFileError(f"{source}: expected a JSON object")
        areas = {
            a: AreaFigures.read(data[a], f"{source} [{a}]") if a in data else None for a in AREAS
        }
        answer_sets = None
        if GROUNDING in data:
            baselines = data.get(BASELINES_KEY, {})
            if not isinstance(baselines, Mapping):
                raise ReportFileError(f"{source}: field {BASELINES_KEY!r} is not an object")
            blocks = [(name, data)]
            blocks += [
                (f"{name} {row_names[b]}", baselines[b]) for b in BASELINES if b in baselines
            ]
            answer_sets = tuple(
                AnswerSetFigures.read(block, label, f"{source} [{label}]")
                for label, block in blocks
            )
        return cls(
            source,
            int(_num(data, NUM_FRAMES, source)) if NUM_FRAMES in data else None,
            areas,
            _subsets(data, BY_TYPE, FRAMES, source),
            _subsets(data, BY_DEPTH, GT_OBJECTS, source),
            answer_sets,
        )

    def need(self, section: str) -> object:
        """The section named by its JSON key (``num_frames``, an area, ``by_prompt_type``,
        ``by_depth``), or the error naming it as missing."""
        value = {
            NUM_FRAMES: self.num_frames,
            BY_TYPE: self.by_type,
            BY_DEPTH: self.by_depth,
            **self.areas,
        }[section]
        if value is None:
            raise ReportFileError(f"{self.source}: missing field {section!r}")
        return value


__all__ = [
    "BASELINES",
    "AnswerSetFigures",
    "AreaFigures",
    "BaselineName",
    "ReportFile",
    "ReportFileError",
    "SubsetFigures",
    "SummaryFigures",
    "class_key",
]
