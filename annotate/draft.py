"""The draft of one prompt-to-box pair: an immutable snapshot and its editing operations.

A :class:`Draft` is an immutable snapshot (frozen dataclasses, tuples of floats): the prompt text,
the boxes it refers to (LiDAR frame, ``x, y, z, l, w, h, yaw`` with ``z`` at the geometric centre,
as everywhere in the project) with their classes, and an explicit "refers to nothing" flag for
prompts that describe no object of the scene. Every editing operation is a method returning a new
snapshot, so a GUI can keep the previous one and diff (boxes carry a stable ``box_id`` that survives
moves and deletions of other boxes: :func:`changed_box`).

The draft holds what the person typed, even when it is not yet valid (an empty prompt, a negative
size, a class outside the metric classes): :mod:`annotate.validation` reports such problems, and the
store refuses to write an invalid draft. Only values that can never be meant (NaN, infinity, a box
without seven numbers) are refused at once with :class:`DraftError`.

Undo / redo and the editor a GUI panel holds: :mod:`annotate.editor`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from scenes.geometry.boxes import wrap_yaw
from scenes.geometry.calib import LIDAR_HEIGHT
from scenes.geometry.classes import object_class


def _mean_size(cls: str) -> tuple[float, float, float]:
    """A new box's size ``(l, w, h)`` in metres: its class's mean size
    (:attr:`scenes.geometry.classes.ObjectClass.mean_size`, of the first preset that has the
    name); a pedestrian's for a name of no class set."""
    try:
        return object_class(cls).mean_size
    except ValueError:
        return object_class("Pedestrian").mean_size


class DraftError(ValueError):
    """An editing operation got an impossible value or an unknown box id."""


def _finite(values: Sequence[float], what: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError) as exc:
        raise DraftError(f"{what}: expected numbers, got {values!r}") from exc
    if not all(math.isfinite(v) for v in out):
        raise DraftError(f"{what}: values must be finite, got {out}")
    return out


def _as_box(box: Sequence[float] | np.ndarray, what: str = "box") -> tuple[float, ...]:
    values = np.asarray(box, dtype=np.float64).reshape(-1)
    if values.shape != (7,):
        raise DraftError(f"{what}: expected 7 values x, y, z, l, w, h, yaw, got {values.size}")
    out = _finite(values, what)
    return (*out[:6], _wrap(out[6]))


def _wrap(yaw: float) -> float:
    """``yaw`` in ``[-pi, pi)``; a value already inside is kept bit for bit (typed 0.4 stays 0.4)."""
    return yaw if -math.pi <= yaw < math.pi else float(wrap_yaw(yaw))


def default_box(
    cls: str, x: float, y: float, ground_z: float = -LIDAR_HEIGHT, yaw: float = 0.0
) -> tuple[float, float, float, float, float, float, float]:
    """A box of the class's mean size standing on the ground at ``(x, y)`` (a ground click).

    ``ground_z`` defaults to the ground of a LiDAR mounted :data:`scenes.geometry.calib.LIDAR_HEIGHT` above
    it; a name of no class set gets the pedestrian's size.
    """
    length, width, height = _mean_size(cls)
    x, y, ground_z, yaw = _finite((x, y, ground_z, yaw), "default box")
    return (x, y, ground_z + height / 2.0, length, width, height, _wrap(yaw))


@dataclass(frozen=True)
class DraftBox:
    """One box of a draft.

    Attributes:
        box_id: Stable id within the draft (not the position in the list).
        box: ``(x, y, z, l, w, h, yaw)`` LiDAR frame, metres / radians, yaw in ``[-pi, pi)``.
        cls: Class name (validation requires one of ``scenes.CLASSES``).
    """

    box_id: int
    box: tuple[float, float, float, float, float, float, float]
    cls: str

    @property
    def array(self) -> np.ndarray:
        """The box as a fresh ``(7,)`` float64 array."""
        return np.array(self.box, dtype=np.float64)


@dataclass(frozen=True)
class Draft:
    """One prompt-to-box pair being edited (an immutable snapshot).

    Attributes:
        prompt: The sentence as typed.
        boxes: The referred boxes, in list order (the order written to ``label_2``).
        refers_to_nothing: The person states that the prompt refers to no object.
        next_box_id: The id the next added box gets.
        sample_id: The saved pair this draft edits (5-digit id), or None for a new pair.
        base_version: The manifest version of that pair when it was opened (0 for a sample that
            was never annotated here); the store refuses an edit when the pair changed since.
    """

    prompt: str = ""
    boxes: tuple[DraftBox, ...] = ()
    refers_to_nothing: bool = False
    next_box_id: int = 0
    sample_id: str | None = None
    base_version: int = 0

    # ---------------------------------------------------------------- construction and views

    @staticmethod
    def from_boxes(
        boxes: np.ndarray | Sequence[Sequence[float]],
        classes: Sequence[str],
        prompt: str = "",
        *,
        refers_to_nothing: bool = False,
        sample_id: str | None = None,
        base_version: int = 0,
    ) -> Draft:
        """A draft holding ``boxes (K, 7)`` with ``classes`` (ids 0..K-1)."""
        arr = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
        if len(arr) != len(classes):
            raise DraftError(f"{len(arr)} boxes but {len(classes)} class names")
        items = tuple(
            DraftBox(i, _as_box(b, f"box {i + 1}"), str(c))
            for i, (b, c) in enumerate(zip(arr, classes, strict=True))
        )
        return Draft(
            prompt=str(prompt),
            boxes=items,
            refers_to_nothing=refers_to_nothing,
            next_box_id=len(items),
            sample_id=sample_id,
            base_version=int(base_version),
        )

    @property
    def box_array(self) -> np.ndarray:
        """All boxes as ``(K, 7)`` float64, LiDAR frame (``(0, 7)`` when empty)."""
        if not self.boxes:
            return np.zeros((0, 7))
        return np.array([b.box for b in self.boxes], dtype=np.float64)

    @property
    def classes(self) -> tuple[str, ...]:
        """Class names in box order."""
        return tuple(b.cls for b in self.boxes)

    @property
    def box_ids(self) -> tuple[int, ...]:
        """Box ids in list order."""
        return tuple(b.box_id for b in self.boxes)

    def index_of(self, box_id: int) -> int:
        """Position of the box with ``box_id``; :class:`DraftError` when there is none."""
        for i, b in enumerate(self.boxes):
            if b.box_id == box_id:
                return i
        raise DraftError(f"no box with id {box_id} in the draft (ids: {list(self.box_ids)})")

    def get(self, box_id: int) -> DraftBox:
        """The box with ``box_id``."""
        return self.boxes[self.index_of(box_id)]

    # ---------------------------------------------------------------- editing operations

    def set_prompt(self, text: str) -> Draft:
        """The prompt replaced by ``text`` (kept as typed; validation and the store strip it)."""
        if not isinstance(text, str):
            raise DraftError(f"prompt: expected text, got {type(text).__name__}")
        return replace(self, prompt=text)

    def set_refers_to_nothing(self, flag: bool) -> Draft:
        """Mark (or unmark) the prompt as referring to no object."""
        return replace(self, refers_to_nothing=bool(flag))

    def add_box(self, box: Sequence[float] | np.ndarray, cls: str) -> Draft:
        """A new box appended (id :attr:`next_box_id`); clears the "refers to nothing" flag."""
        return self.add_boxes(np.asarray(box, dtype=np.float64).reshape(1, -1), [cls])

    def add_boxes(
        self, boxes: np.ndarray | Sequence[Sequence[float]], classes: Sequence[str]
    ) -> Draft:
        """Several boxes ``(K, 7)`` appended at once (e.g. the model's predictions), one edit."""
        arr = np.asarray(boxes, dtype=np.float64)
        arr = arr.reshape(0, 7) if arr.size == 0 else arr.reshape(-1, arr.shape[-1])
        if len(arr) != len(classes):
            raise DraftError(f"{len(arr)} boxes but {len(classes)} class names")
        if not len(arr):
            return self
        added = tuple(
            DraftBox(self.next_box_id + i, _as_box(b, "new box"), str(c))
            for i, (b, c) in enumerate(zip(arr, classes, strict=True))
        )
        return replace(
            self,
            boxes=self.boxes + added,
            next_box_id=self.next_box_id + len(added),
            refers_to_nothing=False,
        )

    def _with_box(self, box_id: int, new: DraftBox) -> Draft:
        i = self.index_of(box_id)
        return replace(self, boxes=(*self.boxes[:i], new, *self.boxes[i + 1 :]))

    def set_box(self, box_id: int, box: Sequence[float] | np.ndarray) -> Draft:
        """All seven values of a box replaced (e.g. by a fitted box)."""
        old = self.get(box_id)
        return self._with_box(box_id, replace(old, box=_as_box(box, f"box id {box_id}")))

    def move_box(self, box_id: int, x: float, y: float, z: float | None = None) -> Draft:
        """The box centre moved to ``(x, y)`` (and ``z`` when given), LiDAR frame."""
        old = self.get(box_id)
        zz = old.box[2] if z is None else z
        xyz = _finite((x, y, zz), f"box id {box_id} position")
        return self._with_box(box_id, replace(old, box=(*xyz, *old.box[3:])))

    def rotate_box(self, box_id: int, yaw: float) -> Draft:
        """The box's yaw set to ``yaw`` (radians, wrapped to ``[-pi, pi)``)."""
        old = self.get(box_id)
        (value,) = _finite((yaw,), f"box id {box_id} yaw")
        return self._with_box(box_id, replace(old, box=(*old.box[:6], _wrap(value))))

    def resize_box(
        self, box_id: int, length: float, width: float, height: float, *, keep_bottom: bool = True
    ) -> Draft:
        """The box's size set to ``(l, w, h)``.

        With ``keep_bottom`` the bottom face stays where it is (the object keeps standing on the
        ground) and the centre's z moves by half the height change; otherwise the centre stays.
        """
        old = self.get(box_id)
        lwh = _finite((length, width, height), f"box id {box_id} size")
        x, y, z = old.box[:3]
        if keep_bottom:
            z = z - old.box[5] / 2.0 + lwh[2] / 2.0
        return self._with_box(box_id, replace(old, box=(x, y, z, *lwh, old.box[6])))

    def set_class(self, box_id: int, cls: str) -> Draft:
        """The box's class set to ``cls``."""
        old = self.get(box_id)
        return self._with_box(box_id, replace(old, cls=str(cls)))

    def delete_box(self, box_id: int) -> Draft:
        """The box removed (the ids of the others do not change)."""
        i = self.index_of(box_id)
        return replace(self, boxes=self.boxes[:i] + self.boxes[i + 1 :])

    def clear(self) -> Draft:
        """An empty draft (no prompt, no boxes) that still edits the same saved pair."""
        return Draft(
            next_box_id=self.next_box_id,
            sample_id=self.sample_id,
            base_version=self.base_version,
        )

    # ---------------------------------------------------------------- serialisation

    def to_json(self) -> dict:
        """A JSON-serialisable dict (for per-client persistence)."""
        return {
            "prompt": self.prompt,
            "boxes": [{"id": b.box_id, "box": list(b.box), "cls": b.cls} for b in self.boxes],
            "refers_to_nothing": self.refers_to_nothing,
            "next_box_id": self.next_box_id,
            "sample_id": self.sample_id,
            "base_version": self.base_version,
        }

    @staticmethod
    def from_json(data: dict) -> Draft:
        """Inverse of :meth:`to_json`."""
        try:
            boxes = tuple(
                DraftBox(int(b["id"]), _as_box(b["box"], f"box id {b['id']}"), str(b["cls"]))
                for b in data.get("boxes", ())
            )
            next_id = int(data.get("next_box_id", 0))
            sample_id = data.get("sample_id")
            return Draft(
                prompt=str(data.get("prompt", "")),
                boxes=boxes,
                refers_to_nothing=bool(data.get("refers_to_nothing", False)),
                next_box_id=max([next_id, *(b.box_id + 1 for b in boxes)]),
                sample_id=None if sample_id is None else str(sample_id),
                base_version=int(data.get("base_version", 0)),
            )
        except (KeyError, TypeError) as exc:
            raise DraftError(f"malformed draft JSON: {exc!r}") from exc


def is_pristine(draft: Draft) -> bool:
    """Whether a draft holds nothing worth keeping (a new pair, no box, no prompt, no mark)."""
    return (
        draft.sample_id is None
        and not draft.boxes
        and not draft.prompt.strip()
        and not draft.refers_to_nothing
    )


def changed_box(before: Draft, after: Draft) -> int | None:
    """The id of the first box of ``after`` that is new or differs from ``before`` (None when
    no box was added or changed, e.g. after a deletion)."""
    old = {b.box_id: b for b in before.boxes}
    for item in after.boxes:
        if old.get(item.box_id) != item:
            return item.box_id
    return None
