"""What every browser's Annotate tab shares: the served root's store and the open tabs.

One :class:`AnnotationHub` per app (:attr:`app.server.Talk2PCApp.annotations`), created with the
app and forgotten with it (:meth:`AnnotationHub.close` in ``app.stop``): nothing is kept at module
level, so a second app in the same process (a test, a restarted server) opens its own store.
The store is opened when the first tab asks for it, and opening it writes nothing
(:class:`annotate.AnnotationStore`): the pairs folder, its lock and its split lists appear with
the first save, so a page that only looks leaves the disk as it was.

The store's root is the served root (a Talk2Radar root with prompts) or the folder named with
``--pairs``: :attr:`AnnotationHub.separate` says which, and the tab says where pairs go. A root
without prompts (a View-of-Delft release served directly) without ``--pairs`` gets no store: the
folder beside it (:func:`app.serving.served.default_pairs_root`) is only suggested, never written, and
the tab says how to name one (:attr:`AnnotationHub.error`). A nuScenes root's pairs are Talk2Car
commands (:class:`annotate.talk2car.Talk2CarStore`), saved only into ``--pairs DIR``. What
differs between the kinds is the root kind's (:mod:`app.serving.served`).
Family specifics: the drives the *Sequence* folder plays are :class:`scenes.talk2radar.drives.Drives`
(the one drive type, which the root kind gives for every family), imported from that room.
"""

from __future__ import annotations

import logging
import threading
import weakref
from pathlib import Path
from typing import Protocol

from annotate import AnnotationStore, StoreError
from annotate.talk2car import Talk2CarStore
from app.serving.served import ServedRoot
from app.session import ClientSession
from scenes.frame import RootError
from scenes.talk2radar.drives import Drives

log = logging.getLogger(__name__)


class PairsView(Protocol):
    """An open tab, as the hub sees it: its browser's session and its list of saved pairs."""

    session: ClientSession

    def refresh_pairs(self) -> None:
        """Re-read the saved pairs into the tab."""


class AnnotationHub:
    """The store of one served root and the open Annotate tabs (see the module docstring).

    Args:
        served: The root kind served (:class:`app.serving.served.ServedRoot`): where pairs go
            (``pairs_path``; ``named`` False: only a suggestion, never written, no store), the
            store it opens there, the frame a pair is made on, the rules a pair must meet beyond
            :func:`annotate.validate`, and the drives of a split.
    """

    def __init__(self, served: ServedRoot) -> None:
        self.served = served
        self.path = Path(served.pairs_path)
        self.named = served.named
        self.served_path = served.root.path
        self._store: AnnotationStore | Talk2CarStore | None = None
        self._error: str | None = None
        self._opened = False
        self._open_lock = threading.Lock()
        self._views: weakref.WeakValueDictionary[int, PairsView] = weakref.WeakValueDictionary()
        self._lock = threading.Lock()
        self._drives: tuple[tuple[str, ...], Drives] | None = None
        self._drives_lock = threading.Lock()
        self.drives_error: str | None = None
        """Why the served split's drives could not be read (None: they could, or not asked)."""

    def _open(self) -> None:
        with self._open_lock:
            if self._opened:
                return
            self._opened = True
            if not self.named:
                self._error = self.served.unnamed_message()
                return
            try:
                self._store = self.served.open_store()
            except (OSError, StoreError, ValueError) as exc:
                self._error = f"{type(exc).__name__}: {exc}"
                log.error("annotation store of %s unavailable: %s", self.path, self._error)

    def saving_line(self) -> str:
        """One line on where pairs go (the console's, at start): the folder they are saved
        into, or why nothing is saved (the tab's "Saving is unavailable")."""
        if self.error is not None:
            return f"Annotation does not save pairs: {self.error}"
        return f"Annotation saves pairs into {self.path}"

    @property
    def separate(self) -> bool:
        """Whether pairs go into another folder than the served root."""
        return self.path.resolve() != Path(self.served_path).resolve()

    @property
    def store(self) -> AnnotationStore | Talk2CarStore | None:
        """The root's store (an :class:`annotate.AnnotationStore`, or a
        :class:`annotate.talk2car.Talk2CarStore` on a nuScenes root), or None when it cannot be
        opened."""
        self._open()
        return self._store

    @property
    def error(self) -> str | None:
        """Why the store could not be opened (None when it could)."""
        self._open()
        return self._error

    def drives(self, ids: tuple[str, ...]) -> Drives:
        """The drives of a split list of the served root (:meth:`app.serving.served.ServedRoot.drives`),
        computed once per list and shared by every browser; none when a pose file is malformed
        (:attr:`drives_error` says which)."""
        key = tuple(ids)
        with self._drives_lock:
            if self._drives is None or self._drives[0] != key:
                try:
                    drives, self.drives_error = self.served.drives(ids), None
                except (RootError, OSError) as exc:
                    drives, self.drives_error = Drives(()), str(exc)
                    log.error("drives of %s: %s", self.served_path, exc)
                self._drives = (key, drives)
            return self._drives[1]

    def register(self, view: PairsView) -> None:
        """Keep ``view`` informed of saved and deleted pairs (until its browser leaves)."""
        with self._lock:
            self._views[id(view)] = view

    def panels(self) -> list[PairsView]:
        """The tabs of the browsers still connected."""
        with self._lock:
            items = list(self._views.values())
        return [v for v in items if not v.session.closed]

    def pairs_changed(self) -> None:
        """Re-list the saved pairs in every connected browser."""
        for view in self.panels():
            try:
                view.refresh_pairs()
            except Exception:  # One browser's failure must not stop the others' update.
                log.exception("client %s: could not re-list the pairs", view.session.client_id)

    def close(self) -> None:
        """Forget the open tabs (the app stopped)."""
        with self._lock:
            self._views.clear()
