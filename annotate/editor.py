"""Undo / redo over drafts, and the editor one client's annotation panel holds.

:class:`History` keeps the snapshots for undo / redo (bounded; a new edit after undos drops the
redo branch; an edit that changes nothing is not recorded). Consecutive edits with the same
``merge_key`` (e.g. the many updates of one gizmo drag) form one undo step. :class:`DraftEditor`
bundles a history with the editing operations: what a per-client GUI panel holds.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, replace
from typing import Any, TypeVar

import numpy as np

from annotate.draft import Draft


@dataclass(frozen=True)
class _Entry:
    draft: Draft
    label: str
    merge_key: Hashable | None = None


class History:
    """Undo / redo over :class:`Draft` snapshots.

    Args:
        initial: The snapshot to start from.
        max_steps: How many undo steps are kept (the oldest are dropped beyond it).
    """

    def __init__(self, initial: Draft | None = None, max_steps: int = 200) -> None:
        if max_steps < 1:
            raise ValueError(f"History.max_steps must be >= 1, got {max_steps}")
        self.max_steps = int(max_steps)
        self._undo: list[_Entry] = []
        self._redo: list[_Entry] = []
        self._present = _Entry(initial if initial is not None else Draft(), "open")
        self.version = 0
        """Counts the changes of the present snapshot (edit, undo, redo, reset): two moments
        with the same version hold the same draft (a save request's key)."""

    def __len__(self) -> int:
        """Number of undo steps available."""
        return len(self._undo)

    @property
    def present(self) -> Draft:
        """The current snapshot."""
        return self._present.draft

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

    @property
    def undo_label(self) -> str | None:
        """What :meth:`undo` would take back (e.g. ``"move box 2"``), or None."""
        return self._present.label if self._undo else None

    @property
    def redo_label(self) -> str | None:
        """What :meth:`redo` would re-apply, or None."""
        return self._redo[-1].label if self._redo else None

    def apply(self, draft: Draft, label: str = "edit", merge_key: Hashable | None = None) -> Draft:
        """Record ``draft`` as the new present snapshot and return it.

        An unchanged draft records nothing. When ``merge_key`` is not None and equals the key of
        the edit that made the present snapshot (and there is nothing to redo), the new snapshot
        replaces the present one: both edits are undone together.
        """
        if draft == self._present.draft:
            return draft
        entry = _Entry(draft, label, merge_key)
        merging = (
            merge_key is not None
            and self._present.merge_key == merge_key
            and self._undo
            and not self._redo
        )
        if not merging:
            self._undo.append(self._present)
            del self._undo[: max(0, len(self._undo) - self.max_steps)]
        self._redo.clear()
        self._present = entry
        self.version += 1
        return draft

    def undo(self) -> Draft:
        """Step back one edit (no-op when there is none); returns the present snapshot."""
        if self._undo:
            self._redo.append(self._present)
            self._present = replace(self._undo.pop(), merge_key=None)
            self.version += 1
        return self.present

    def redo(self) -> Draft:
        """Re-apply the last undone edit (no-op when there is none)."""
        if self._redo:
            self._undo.append(self._present)
            self._present = replace(self._redo.pop(), merge_key=None)
            self.version += 1
        return self.present

    def reset(self, draft: Draft) -> Draft:
        """Forget the history and start from ``draft`` (after a save or when opening a pair)."""
        self._undo.clear()
        self._redo.clear()
        self._present = _Entry(draft, "open")
        self.version += 1
        return draft


_F = TypeVar("_F", bound=Callable[..., Any])


def _serialised(method: _F) -> _F:
    """Run an editor method under the editor's lock (GUI callbacks may arrive on several threads)."""

    @functools.wraps(method)
    def wrapper(self: DraftEditor, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            return method(self, *args, **kwargs)

    return wrapper  # type: ignore[return-value]


class DraftEditor:
    """A draft with its history: the state of one client's annotation panel.

    Every method applies one undoable edit and returns the new snapshot (``add_box`` returns the
    new box's id). ``merge_key`` lets a caller fold a stream of updates (a gizmo drag) into one
    undo step: pass the same hashable key for the whole drag. Methods are serialised by a lock, so
    callbacks of one client arriving on different threads cannot interleave an edit.
    """

    def __init__(self, draft: Draft | None = None, max_steps: int = 200) -> None:
        self.history = History(draft if draft is not None else Draft(), max_steps=max_steps)
        self._lock = threading.RLock()
        self.reset_listeners: list[Callable[[Draft], None]] = []
        """Called with the new draft after every :meth:`reset` (a save, an opened pair)."""

    @property
    def draft(self) -> Draft:
        """The current snapshot."""
        return self.history.present

    @property
    def version(self) -> int:
        """The draft's version (:attr:`History.version`)."""
        return self.history.version

    def _apply(self, draft: Draft, label: str, merge_key: Hashable | None = None) -> Draft:
        return self.history.apply(draft, label, merge_key)

    def _name(self, box_id: int) -> str:
        return f"box {self.draft.index_of(box_id) + 1}"

    @_serialised
    def set_prompt(self, text: str, merge_key: Hashable | None = "prompt") -> Draft:
        """Set the prompt; consecutive prompt edits merge into one undo step by default."""
        return self._apply(self.draft.set_prompt(text), "edit prompt", merge_key)

    @_serialised
    def set_refers_to_nothing(self, flag: bool) -> Draft:
        label = "mark as referring to nothing" if flag else "unmark 'refers to nothing'"
        return self._apply(self.draft.set_refers_to_nothing(flag), label)

    @_serialised
    def add_box(self, box: Sequence[float] | np.ndarray, cls: str) -> int:
        """Add one box; returns its id."""
        new = self.draft.add_box(box, cls)
        self._apply(new, f"add {cls} box")
        return new.boxes[-1].box_id

    @_serialised
    def add_boxes(self, boxes: np.ndarray, classes: Sequence[str]) -> tuple[int, ...]:
        """Add several boxes in one undo step; returns their ids."""
        before = len(self.draft.boxes)
        new = self.draft.add_boxes(boxes, classes)
        self._apply(new, f"add {len(new.boxes) - before} boxes")
        return new.box_ids[before:]

    @_serialised
    def set_box(self, box_id: int, box: Sequence[float] | np.ndarray, label: str = "") -> Draft:
        return self._apply(self.draft.set_box(box_id, box), label or f"set {self._name(box_id)}")

    @_serialised
    def move_box(
        self,
        box_id: int,
        x: float,
        y: float,
        z: float | None = None,
        merge_key: Hashable | None = None,
    ) -> Draft:
        return self._apply(
            self.draft.move_box(box_id, x, y, z), f"move {self._name(box_id)}", merge_key
        )

    @_serialised
    def rotate_box(self, box_id: int, yaw: float, merge_key: Hashable | None = None) -> Draft:
        return self._apply(
            self.draft.rotate_box(box_id, yaw), f"rotate {self._name(box_id)}", merge_key
        )

    @_serialised
    def resize_box(
        self,
        box_id: int,
        length: float,
        width: float,
        height: float,
        merge_key: Hashable | None = None,
    ) -> Draft:
        return self._apply(
            self.draft.resize_box(box_id, length, width, height),
            f"resize {self._name(box_id)}",
            merge_key,
        )

    @_serialised
    def set_class(self, box_id: int, cls: str) -> Draft:
        return self._apply(self.draft.set_class(box_id, cls), f"{self._name(box_id)} -> {cls}")

    @_serialised
    def delete_box(self, box_id: int) -> Draft:
        return self._apply(self.draft.delete_box(box_id), f"delete {self._name(box_id)}")

    @_serialised
    def apply(self, draft: Draft, label: str, merge_key: Hashable | None = None) -> Draft:
        """Record a snapshot made by several :class:`Draft` operations as one edit (e.g. the
        referents chosen for a sentence: some boxes deleted, others added)."""
        return self._apply(draft, label, merge_key)

    @_serialised
    def clear(self) -> Draft:
        return self._apply(self.draft.clear(), "clear")

    @_serialised
    def undo(self) -> Draft:
        return self.history.undo()

    @_serialised
    def redo(self) -> Draft:
        return self.history.redo()

    @_serialised
    def reset(self, draft: Draft | None = None) -> Draft:
        """Start over from ``draft`` (default: an empty draft) with an empty history."""
        out = self.history.reset(draft if draft is not None else Draft())
        for listener in list(self.reset_listeners):
            listener(out)
        return out
