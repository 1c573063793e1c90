"""Validation of a draft before it is saved: one clear message per problem.

Errors block a save; warnings are shown but do not. Messages are for people: boxes are named
"box 2 of 3 (Car)", counting from 1 in list order; :attr:`Issue.box_index` carries the 0-based
position and :attr:`Issue.field` a machine-readable field name (``prompt``, ``boxes``,
``box[1].size``, ``box[1].class``, ``box[1].position``, ``box[1].image``, ...).

Errors:

- the prompt is empty (after stripping), or the text policy refuses it
  (:func:`scenes.utils.text_policy.clean_text`: a control, invisible or line-break character, named in
  the message, since a Talk2Radar prompt file is one sentence and readers keep internal line
  breaks; more than 500 characters);
- no box and the "refers to nothing" flag not set; or the flag set while boxes remain;
- a box with a non-finite value, a non-positive size or a size above ``max_size``;
- a class outside the allowed classes (``ValidationConfig.classes``: the served model's class
  set; ``Car``, ``Pedestrian``, ``Cyclist`` by default);
- a box centre outside the annotated range: ``x`` in ``[0, 51.2]``, ``|y| <= 25.6`` (the model's
  BEV grid) and ``z`` in ``[-5, 5]`` m, all configurable;
- when a camera calibration is given and ``require_in_image`` is set: a box that does not project
  into the camera image at all. Decision: View-of-Delft annotates only objects at least partly
  inside the camera field of view, and the official evaluation scores a box through its projected
  2D box, so a box wholly outside the image could never be scored.

Warnings: a projected 2D box whose height is at most 40 px (the official evaluation ignores such
ground truth), two boxes that overlap heavily in bird's eye view (a duplicate?), a prompt longer
than Talk2Radar's 30 text tokens (counted as words).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from annotate.draft import Draft
from scenes.geometry.boxes import bev_iou
from scenes.geometry.calib import IMAGE_SIZE, Calibration, boxes_2d, boxes_lidar_to_camera
from scenes.geometry.classes import VOD
from scenes.utils.text_policy import ANNOTATOR, PROMPT, TextPolicyError, TextRule, clean_text

MIN_EVAL_HEIGHT_PX = 40.0
"""The official VoD evaluation ignores ground truth whose 2D box is at most this tall."""


class Severity(enum.Enum):
    """How serious an :class:`Issue` is."""

    ERROR = "error"
    WARNING = "warning"


@dataclass(frozen=True)
class Issue:
    """One validation finding.

    Attributes:
        field: What it is about (``prompt``, ``boxes``, ``box[i].size``, ...; ``i`` 0-based).
        message: A sentence for the person.
        box_index: 0-based box position, or None for draft-level issues.
        severity: Error (blocks saving) or warning.
    """

    field: str
    message: str
    box_index: int | None = None
    severity: Severity = Severity.ERROR


@dataclass(frozen=True)
class ValidationConfig:
    """Rules of :func:`validate`.

    Attributes:
        x_range: Allowed box-centre ``x`` (m, LiDAR frame), inclusive.
        y_max: Largest allowed ``|y|`` of a box centre (m).
        z_range: Allowed box-centre ``z`` (m).
        max_size: Largest allowed length, width or height (m): catches typing slips.
        classes: Allowed class names.
        require_in_image: With a calibration, reject boxes that do not project into the image.
        image_size: Camera image ``(width, height)`` in pixels.
        max_prompt_words: Longer prompts get a warning (Talk2Radar keeps 30 tokens).
        duplicate_iou: Two boxes with a BEV IoU at least this large get a warning.
    """

    x_range: tuple[float, float] = (0.0, 51.2)
    y_max: float = 25.6
    z_range: tuple[float, float] = (-5.0, 5.0)
    max_size: float = 20.0
    classes: tuple[str, ...] = VOD.names
    require_in_image: bool = True
    image_size: tuple[int, int] = IMAGE_SIZE
    max_prompt_words: int = 30
    duplicate_iou: float = 0.7

    def __post_init__(self) -> None:
        if not self.x_range[0] < self.x_range[1]:
            raise ValueError(f"ValidationConfig: empty x_range {self.x_range}")
        if not self.z_range[0] < self.z_range[1]:
            raise ValueError(f"ValidationConfig: empty z_range {self.z_range}")
        if self.y_max <= 0 or self.max_size <= 0:
            raise ValueError("ValidationConfig: y_max and max_size must be positive")


@dataclass(frozen=True)
class ValidationReport:
    """The findings for one draft."""

    issues: tuple[Issue, ...] = ()

    @property
    def errors(self) -> tuple[Issue, ...]:
        return tuple(i for i in self.issues if i.severity is Severity.ERROR)

    @property
    def warnings(self) -> tuple[Issue, ...]:
        return tuple(i for i in self.issues if i.severity is Severity.WARNING)

    @property
    def ok(self) -> bool:
        """True when nothing blocks saving."""
        return not self.errors

    def messages(self, severity: Severity | None = Severity.ERROR) -> list[str]:
        """The messages of the given severity (all of them with None)."""
        return [i.message for i in self.issues if severity is None or i.severity is severity]

    def raise_if_invalid(self) -> None:
        """Raise :class:`ValidationError` when there is an error."""
        if not self.ok:
            raise ValidationError(self.errors)


class ValidationError(ValueError):
    """A draft cannot be saved; :attr:`issues` holds every error (the message lists them)."""

    def __init__(self, issues: Sequence[Issue]) -> None:
        self.issues = tuple(issues)
        lines = "\n".join(f"- {i.message}" for i in self.issues)
        super().__init__(f"the pair cannot be saved:\n{lines}")


def _fmt(v: float) -> str:
    return f"{v:.2f}"


def _box_name(i: int, k: int, cls: str) -> str:
    return f"box {i + 1} of {k} ({cls})"


def validate(
    draft: Draft, config: ValidationConfig | None = None, calib: Calibration | None = None
) -> ValidationReport:
    """Check a draft; ``calib`` (LiDAR -> camera) enables the image checks.

    Returns:
        A report with every error and warning, in order: prompt, box set, then box by box.
    """
    cfg = config if config is not None else ValidationConfig()
    issues: list[Issue] = []
    try:
        text: str | None = clean_text(draft.prompt, PROMPT)
    except TextPolicyError as exc:
        issues.append(Issue("prompt", str(exc)))
        text = None
    if text == "":
        issues.append(Issue("prompt", "the prompt is empty: type the sentence the boxes answer"))
    elif text is not None and len(text.split()) > cfg.max_prompt_words:
        issues.append(
            Issue(
                "prompt",
                f"the prompt has {len(text.split())} words; text encoders keep about "
                f"{cfg.max_prompt_words} tokens, so the end may be cut",
                severity=Severity.WARNING,
            )
        )
    k = len(draft.boxes)
    if k == 0 and not draft.refers_to_nothing:
        issues.append(
            Issue(
                "boxes",
                "no boxes: add at least one box, or mark the prompt as referring to nothing",
            )
        )
    if k and draft.refers_to_nothing:
        issues.append(
            Issue(
                "boxes",
                f"the prompt is marked as referring to nothing but the draft has {k} box(es): "
                "delete them or clear the mark",
            )
        )
    sane = []
    for i, item in enumerate(draft.boxes):
        name = _box_name(i, k, item.cls)
        x, y, z, length, width, height, _ = item.box
        if not all(math.isfinite(v) for v in item.box):
            issues.append(Issue(f"box[{i}].value", f"{name}: a value is not a finite number", i))
            continue
        if item.cls not in cfg.classes:
            issues.append(
                Issue(
                    f"box[{i}].class",
                    f"box {i + 1} of {k}: class {item.cls!r} is not one of {', '.join(cfg.classes)}",
                    i,
                )
            )
        ok_size = True
        for label, value in (("length", length), ("width", width), ("height", height)):
            if value <= 0:
                issues.append(
                    Issue(f"box[{i}].size", f"{name}: {label} must be positive, got {value:g} m", i)
                )
                ok_size = False
            elif value > cfg.max_size:
                issues.append(
                    Issue(
                        f"box[{i}].size",
                        f"{name}: {label} {value:g} m is larger than {cfg.max_size:g} m",
                        i,
                    )
                )
                ok_size = False
        x0, x1 = cfg.x_range
        z0, z1 = cfg.z_range
        in_range = True
        if not x0 <= x <= x1:
            issues.append(
                Issue(
                    f"box[{i}].position",
                    f"{name}: centre x = {_fmt(x)} m is outside the annotated range "
                    f"[{x0:g}, {x1:g}] m",
                    i,
                )
            )
            in_range = False
        if abs(y) > cfg.y_max:
            issues.append(
                Issue(
                    f"box[{i}].position",
                    f"{name}: centre y = {_fmt(y)} m is outside the annotated range "
                    f"|y| <= {cfg.y_max:g} m",
                    i,
                )
            )
            in_range = False
        if not z0 <= z <= z1:
            issues.append(
                Issue(
                    f"box[{i}].position",
                    f"{name}: centre z = {_fmt(z)} m is outside [{z0:g}, {z1:g}] m",
                    i,
                )
            )
            in_range = False
        if ok_size:
            sane.append(i)
            if calib is not None and in_range:
                issues.extend(_image_issues(i, name, item.array, calib, cfg))
    if len(sane) > 1:
        arr = draft.box_array[sane]
        iou = bev_iou(arr, arr)
        for a in range(len(sane)):
            for b in range(a + 1, len(sane)):
                if iou[a, b] >= cfg.duplicate_iou:
                    issues.append(
                        Issue(
                            f"box[{sane[b]}].position",
                            f"boxes {sane[a] + 1} and {sane[b] + 1} overlap (BEV IoU "
                            f"{iou[a, b]:.2f}): is one a duplicate?",
                            sane[b],
                            Severity.WARNING,
                        )
                    )
    return ValidationReport(tuple(issues))


def _image_issues(
    i: int, name: str, box: np.ndarray, calib: Calibration, cfg: ValidationConfig
) -> list[Issue]:
    cam = boxes_lidar_to_camera(box[None], calib)
    # Depth of the box centre in the camera frame (the bottom centre is stored; add half height).
    centre_depth = float((calib.velo_to_cam @ np.r_[box[:3], 1.0])[2])
    x1, y1, x2, y2 = boxes_2d(cam, calib, cfg.image_size)[0]
    if centre_depth <= 0 or x2 - x1 <= 0 or y2 - y1 <= 0:
        if not cfg.require_in_image:
            return []
        return [
            Issue(
                f"box[{i}].image",
                f"{name}: the box is outside the camera image, so the official evaluation "
                "could not score it; annotate objects inside the camera's field of view",
                i,
            )
        ]
    if y2 - y1 <= MIN_EVAL_HEIGHT_PX:
        return [
            Issue(
                f"box[{i}].image",
                f"{name}: only {y2 - y1:.0f} px tall in the image; the official evaluation "
                f"ignores ground truth up to {MIN_EVAL_HEIGHT_PX:.0f} px",
                i,
                Severity.WARNING,
            )
        ]
    return []


def clean_field(text: object, rule: TextRule, field: str) -> str:
    """``text`` in the text policy's form under ``rule`` (:func:`scenes.utils.text_policy.clean_text`).

    Raises:
        ValidationError: the policy refuses it (one issue of ``field``, e.g. ``annotator``).
    """
    try:
        return clean_text(text, rule)
    except TextPolicyError as exc:
        raise ValidationError((Issue(field, str(exc)),)) from None


def clean_annotator(name: object) -> str:
    """The annotator (or reviewer) name as the manifest records it: :func:`clean_field` under
    :data:`scenes.utils.text_policy.ANNOTATOR`, ``anonymous`` when empty."""
    return clean_field(name, ANNOTATOR, "annotator") or "anonymous"


def clean_prompt(draft: Draft) -> Draft:
    """``draft`` with its prompt in the text policy's form, as it is saved (:func:`validate`
    has accepted the prompt)."""
    return draft.set_prompt(clean_text(draft.prompt, PROMPT))
