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
folder beside it (:func:`app.server.default_pairs_root`) is only suggested, never written, and
the tab says how to name one (:attr:`AnnotationHub.error`).
"""

from __future__ import annotations

import logging
import threading
import weakref
from pathlib import Path
from typing import Protocol

from annotate import AnnotationStore, StoreError
from app.session import ClientSession
from scenes.talk2radar.drives import Drives, find_drives
from scenes.talk2radar.layout import RootError
from scenes.talk2radar.root import Talk2RadarRoot

log = logging.getLogger(__name__)


class PairsView(Protocol):
    """An open tab, as the hub sees it: its browser's session and its list of saved pairs."""

    session: ClientSession

    def refresh_pairs(self) -> None:
        """Re-read the saved pairs into the tab."""


class AnnotationHub:
    """The store of one served root and the open Annotate tabs (see the module docstring).

    Args:
        path: The root pairs are saved into.
        radar_folder: The radar tree written there (the served root's, so that a pair's radar
            file keeps its tree name: ``radar`` is a single scan; a store root that has another
            tree is refused with a message naming both); None: the store's default.
        served: The root being served (None: ``path``).
        named: Whether the person named ``path`` (the served root, or ``--pairs``); False: it is
            only the suggestion for a root without prompts, never written (no store).
    """

    def __init__(
        self,
        path: Path,
        radar_folder: str | None = None,
        served: Talk2RadarRoot | None = None,
        *,
        named: bool = True,
    ) -> None:
        self.path = Path(path)
        self.named = named
        self.radar_folder = radar_folder
        self.served_path = served.path if served is not None else self.path
        self._store: AnnotationStore | None = None
        self._error: str | None = None
        self._opened = False
        self._open_lock = threading.Lock()
        self._views: weakref.WeakValueDictionary[int, PairsView] = weakref.WeakValueDictionary()
        self._lock = threading.Lock()
        self._drives: tuple[tuple[str, tuple[str, ...]], Drives] | None = None
        self._drives_lock = threading.Lock()
        self.drives_error: str | None = None
        """Why the served split's drives could not be read (None: they could, or not asked)."""

    def _open(self) -> None:
        with self._open_lock:
            if self._opened:
                return
            self._opened = True
            if not self.named:
                self._error = (
                    f"the served root has no prompts (a release as it comes), and pairs are "
                    f"never written beside it unless you say where: restart with --pairs DIR "
                    f"(e.g. --pairs {self.path})"
                )
                return
            try:
                self._store = AnnotationStore(self.path, radar_folder=self.radar_folder)
            except (OSError, StoreError, ValueError) as exc:
                self._error = f"{type(exc).__name__}: {exc}"
                log.error("annotation store of %s unavailable: %s", self.path, self._error)

    @property
    def separate(self) -> bool:
        """Whether pairs go into another folder than the served root."""
        return self.path.resolve() != Path(self.served_path).resolve()

    @property
    def store(self) -> AnnotationStore | None:
        """The root's :class:`annotate.AnnotationStore`, or None when it cannot be opened."""
        self._open()
        return self._store

    @property
    def error(self) -> str | None:
        """Why the store could not be opened (None when it could)."""
        self._open()
        return self._error

    def drives(self, root: Talk2RadarRoot, ids: tuple[str, ...]) -> Drives:
        """The drives of a split list of ``root`` (:func:`scenes.talk2radar.drives.find_drives`), computed
        once per list and shared by every browser; none when a pose file is malformed
        (:attr:`drives_error` says which)."""
        key = (str(root.path), tuple(ids))
        with self._drives_lock:
            if self._drives is None or self._drives[0] != key:
                try:
                    drives, self.drives_error = find_drives(root, ids), None
                except (RootError, OSError) as exc:
                    drives, self.drives_error = Drives(()), str(exc)
                    log.error("drives of %s: %s", root.path, exc)
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
