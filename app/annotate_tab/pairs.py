"""Saving, reopening and deleting pairs from the Annotate tab: :class:`PairActions`.

The store's work runs outside the session's lock (it takes the store's own lock and may wait for
another browser's save); after a save or a deletion the served split is re-read (the navigator's
``reload``) and every browser's list of saved pairs is refreshed (the hub).

Saves are idempotent per draft version: a save request's key is this tab's token and its
editor's :attr:`annotate.DraftEditor.version`, so two requests for one draft (a double click, a
click and Enter, a scripted burst on several threads) save once and both tell the same pair
(:meth:`annotate.AnnotationStore.save`'s ``request``). A request arriving after that save reset
the draft, with nothing edited since, is answered with the same result too.
"""

from __future__ import annotations

import logging
import uuid
from pathlib import Path

from annotate import (
    ConflictError,
    SaveResult,
    StoreError,
    ValidationError,
    is_pristine,
)
from app.annotate_tab.formatting import option_pair_id
from app.annotate_tab.panel import AnnotationPanel, DraftFrame
from app.serving.navigation import estimate_ground_z
from scenes.datasets.source import Talk2RadarRoot

log = logging.getLogger(__name__)


class PairActions:
    """The saved-pair actions of one browser's tab (wired by :mod:`app.annotate_tab.tab`).

    Args:
        panel: The tab's state and drawing.
    """

    def __init__(self, panel: AnnotationPanel) -> None:
        self.panel = panel
        self._token = uuid.uuid4().hex
        """This tab's part of its save requests' keys."""
        self._last_save: tuple[int, SaveResult] | None = None
        """``(editor version after the reset, result)`` of this tab's last save."""

    def submit(self) -> None:
        """Enter in *Pair prompt*: save when nothing blocks it, else say what does."""
        p = self.panel
        with p.session.lock:
            report = p.report
        if report.ok and p.store is not None:
            self.save()
        else:
            reasons = report.messages()
            if p.store is None:
                reasons.append(f"Saving is unavailable: {p.hub.error}")
            p.notify("Not saved yet", "\n".join(reasons))

    def save(self) -> SaveResult | None:
        """Save the draft (a new pair, or a new version of the reopened pair); the panel's
        status line then names the pair written, and the box fields are cleared. Returns what
        the store saved (None: nothing, a notification says why; also for a repeated request,
        which the first one's answer covers)."""
        p = self.panel
        store = p.store
        with p.session.lock:
            draft, frame, version = p.editor.draft, p.frame, p.editor.version
            split, annotator = p.pair_split() or p.w.split.value, p.w.annotator.value
            last = self._last_save
        if last is not None and last[0] == version:  # saved, nothing edited since
            self._tell_saved(last[1], again=True)
            return
        if store is None:
            p.notify("Saving is unavailable", str(p.hub.error), color="red")
            return
        if frame is None:
            return
        try:
            source = None
            if draft.sample_id is None:
                source = p.hub.served.source_frame(frame.sample)
            request = f"{self._token}:{version}"
            result = store.save(draft, source, annotator=annotator, split=split, request=request)
        except ValidationError as exc:
            p.notify("Cannot save the pair", "\n".join(i.message for i in exc.issues), color="red")
            return
        except ConflictError as exc:
            p.notify("The pair changed meanwhile", str(exc), color="red")
            return
        except (StoreError, OSError, ValueError) as exc:
            log.error("client %s: save failed: %s", p.session.client_id, exc)
            p.notify("Save failed", str(exc), color="red")
            return
        self._tell_saved(result, again=result.repeated)
        if result.repeated:  # the first request resets the draft and refreshes
            return
        log.info(
            "client %s: saved pair %s v%d", p.session.client_id, result.sample_id, result.version
        )
        with p.session.lock:
            p.last_pair = (draft, frame)
            p.last_saved = f"pair {result.sample_id} ({_where(result)}) in " + ", ".join(
                result.record.splits
            )
            if p.editor.version == version:  # (an edit made meanwhile is kept)
                p.editor.reset()
                p.selected = None
                p.bind_to_screen()
                self._last_save = (p.editor.version, result)
        self._after_store_change()
        return result

    def _tell_saved(self, result: SaveResult, again: bool) -> None:
        p = self.panel
        warnings = "".join(f"\n{w.message}" for w in result.warnings)
        where = p.store.path if p.store is not None else p.hub.path
        p.notify(
            f"Saved pair {result.sample_id}",
            f"{_where(result)} in {', '.join(result.record.splits)} of {where}.{warnings}"
            + ("\n(Already saved: nothing changed since.)" if again else ""),
            color="green",
        )

    def _after_store_change(self) -> None:
        p = self.panel
        store = p.store
        root = p.navigator.frames.root
        if store is not None and Path(store.path).resolve() == Path(root.path).resolve():
            try:
                p.navigator.reload()
            except Exception as exc:
                p.session.report_error("Could not re-read the split", exc)
        p.hub.pairs_changed()
        p.refresh()

    def _selected_pair(self) -> str | None:
        sid = option_pair_id(self.panel.w.pair.value)
        return sid if sid in self.panel.pair_ids else None

    def open_selected_pair(self) -> None:
        """Reopen the pair chosen in *Pair* into the draft (asks first about unsaved edits)."""
        p = self.panel
        sid = self._selected_pair()
        if sid is None:
            return
        if p.editor.history.can_undo and not is_pristine(p.editor.draft):
            p.confirm(
                f"Open pair {sid}?",
                "The draft has unsaved changes. Open the pair and discard them?",
                "Discard and open",
                lambda: self.open_pair(sid),
            )
        else:
            self.open_pair(sid)

    def open_pair(self, sample_id: str) -> None:
        """Reopen a saved pair for editing and show its frame. A pair saved beside the served
        root is read from the store's root, and its frame on screen is the served root's sample
        it was annotated on (its own id means nothing there)."""
        p = self.panel
        store = p.store
        if store is None:
            return
        root = p.navigator.frames.root
        separate = p.hub.separate
        try:
            draft = store.open(sample_id)
            sample = (Talk2RadarRoot(store.path) if separate else root).load(sample_id)
        except (StoreError, OSError, ValueError) as exc:
            p.notify(f"Cannot open pair {sample_id}", str(exc), color="red")
            return
        ids = set() if separate else {sample_id}
        history = store.history(sample_id)
        source = dict(history[-1].source) if history else {}
        same_root = bool(source.get("root")) and (
            Path(str(source["root"])).resolve() == Path(root.path).resolve()
        )
        if same_root and source.get("sample_id"):
            ids.add(str(source["sample_id"]))
        with p.session.lock:
            p.editor.reset(draft)
            p.selected = draft.boxes[0].box_id if draft.boxes else None
            p.frame = DraftFrame(sample, estimate_ground_z(sample.lidar), frozenset(ids))
            on_screen = p.on_screen()
        if not on_screen:
            p.back_to_draft_frame()
        p.refresh()

    def delete_selected_pair(self) -> None:
        """Delete the pair chosen in *Pair* (after a confirmation)."""
        sid = self._selected_pair()
        if sid is None:
            return
        self.panel.confirm(
            f"Delete pair {sid}?",
            "The pair disappears from its split; its files and its history stay on disk.",
            "Delete the pair",
            lambda: self.delete_pair(sid),
        )

    def delete_pair(self, sample_id: str) -> None:
        """Delete a saved pair from the root."""
        p = self.panel
        store = p.store
        if store is None:
            return
        try:
            store.delete(sample_id, annotator=p.w.annotator.value)
        except (StoreError, OSError, ValueError) as exc:
            p.notify(f"Cannot delete pair {sample_id}", str(exc), color="red")
            return
        p.notify("Pair deleted", f"Pair {sample_id} was removed from its split.", color="green")
        self._after_store_change()


def _where(result: SaveResult) -> str:
    return "new pair" if result.version == 1 else f"version {result.version}"
