"""Results of the VoD protocol: per class, per area and per evaluation, with their tables."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from model.evaluation.protocol import AREAS
from model.evaluation.report_file import MAOS, MAP_3D, MAP_BEV, R40, class_key


@dataclass(frozen=True)
class APValue:
    """One AP (or AOS) in percent at 11 and 40 recall points."""

    r11: float
    r40: float


@dataclass(frozen=True)
class ClassResult:
    """One class in one area.

    Attributes:
        name: ``Car``, ``Pedestrian`` or ``Cyclist``.
        num_gt: Valid ground-truth objects (class matches, not ignored).
        ap_3d: 3D AP. ap_bev: BEV AP. aos: AOS (from the 2D pass). ap_2d: 2D image-box AP.
    """

    name: str
    num_gt: int
    ap_3d: APValue
    ap_bev: APValue
    aos: APValue
    ap_2d: APValue


@dataclass(frozen=True)
class AreaResult:
    """All classes in one area (entire annotated area or driving corridor)."""

    classes: tuple[ClassResult, ...]

    def __getitem__(self, name: str) -> ClassResult:
        for c in self.classes:
            if c.name.lower() == name.lower():
                return c
        raise KeyError(name)

    def _mean(self, attr: str, points: str) -> float:
        return float(np.mean([getattr(getattr(c, attr), points) for c in self.classes]))

    @property
    def map_3d(self) -> float:
        """mAP 3D at 11 points (the headline)."""
        return self._mean("ap_3d", "r11")

    @property
    def map_bev(self) -> float:
        return self._mean("ap_bev", "r11")

    @property
    def maos(self) -> float:
        return self._mean("aos", "r11")

    @property
    def map_3d_r40(self) -> float:
        return self._mean("ap_3d", "r40")

    @property
    def map_bev_r40(self) -> float:
        return self._mean("ap_bev", "r40")

    @property
    def maos_r40(self) -> float:
        return self._mean("aos", "r40")

    def to_dict(self) -> dict[str, float]:
        """The devkit's keys (``Car_3d_all``, ``Car_bev_all``, ``Car_aos_all``, ...) at 11 points,
        the same with suffix ``_R40``, and ``mAP_3d``, ``mAP_bev``, ``mAOS`` (also ``_R40``):
        :mod:`model.evaluation.report_file`'s keys."""
        out: dict[str, float] = {}
        for r40 in (False, True):
            for c in self.classes:
                ap = (c.ap_3d, c.ap_bev, c.aos)
                for kind, value in zip(("3d", "bev", "aos"), ap, strict=True):
                    out[class_key(c.name, kind, r40)] = value.r40 if r40 else value.r11
        out[MAP_3D] = self.map_3d
        out[MAP_BEV] = self.map_bev
        out[MAOS] = self.maos
        out[MAP_3D + R40] = self.map_3d_r40
        out[MAP_BEV + R40] = self.map_bev_r40
        out[MAOS + R40] = self.maos_r40
        return out


@dataclass(frozen=True)
class VodResult:
    """The official evaluation of a set of frames.

    Attributes:
        entire_area: Results over the entire annotated area.
        roi: Results in the driving corridor.
        num_frames: Frames evaluated.
        unknown_gt_classes: Ground-truth class names that are neither scored nor known (see
            :data:`KNOWN_OTHER_CLASSES`) -> number of objects; they count for no class.
        unknown_dt_classes: The same for the detections.
    """

    entire_area: AreaResult
    roi: AreaResult
    num_frames: int
    unknown_gt_classes: Mapping[str, int] = field(default_factory=dict)
    unknown_dt_classes: Mapping[str, int] = field(default_factory=dict)

    def area(self, name: str) -> AreaResult:
        """``"entire_area"`` or ``"roi"``."""
        if name not in AREAS:
            raise KeyError(f"unknown area {name!r}; expected one of {AREAS}")
        return self.entire_area if name == "entire_area" else self.roi

    def to_dict(self) -> dict[str, dict[str, float]]:
        """``{"entire_area": {...}, "roi": {...}}`` with :meth:`AreaResult.to_dict` inside."""
        return {"entire_area": self.entire_area.to_dict(), "roi": self.roi.to_dict()}

    def unknown_classes_note(self) -> str | None:
        """One line naming the unknown class names left out of the metric, or None."""
        parts = []
        for what, counts in (
            ("ground-truth", self.unknown_gt_classes),
            ("detection", self.unknown_dt_classes),
        ):
            if counts:
                names = ", ".join(f"{name!r} x{n}" for name, n in counts.items())
                parts.append(f"{sum(counts.values())} {what} object(s) ({names})")
        if not parts:
            return None
        return (
            "Not scored, unknown class name: "
            + "; ".join(parts)
            + f" (the classes are {', '.join(c.name for c in self.entire_area.classes)})"
        )

    def format_table(self) -> str:
        """A plain-text summary: class x {3D, BEV, AOS} x {entire area, corridor}, R11 / R40."""
        lines = []
        titles = {"entire_area": "Entire annotated area", "roi": "Driving corridor"}
        w = max([12, *(len(c.name) + 1 for c in self.entire_area.classes)])  # the name column
        header = f"{'':<{w}}{'#GT':>5}  {'3D R11 / R40':>15}  {'BEV R11 / R40':>15}  {'AOS R11 / R40':>15}"
        for name in AREAS:
            res = self.area(name)
            lines.append(f"{titles[name]} ({self.num_frames} frames)")
            lines.append(header)
            for c in res.classes:
                lines.append(
                    f"{c.name:<{w}}{c.num_gt:>5}  {_pair(c.ap_3d.r11, c.ap_3d.r40)}  "
                    f"{_pair(c.ap_bev.r11, c.ap_bev.r40)}  {_pair(c.aos.r11, c.aos.r40)}"
                )
            lines.append(
                f"{'mean':<{w}}{'':>5}  {_pair(res.map_3d, res.map_3d_r40)}  "
                f"{_pair(res.map_bev, res.map_bev_r40)}  {_pair(res.maos, res.maos_r40)}"
            )
            lines.append("")
        note = self.unknown_classes_note()
        if note is not None:
            lines.append(note)
        return "\n".join(lines).rstrip() + "\n"


def _pair(r11: float, r40: float) -> str:
    return f"{r11:6.2f} / {r40:6.2f}"
