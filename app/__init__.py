"""The viser front, cut by concept: the Query tab (:mod:`app.query`), what a browser sees of a
frame (:mod:`app.view`), what the app serves (:mod:`app.serving`) and the Annotate tab
(:mod:`app.annotate_tab`), under the app object and one browser's session.

``python launch.py`` serves it; :class:`Talk2PCApp` is the app object (start / stop, port 0 for
tests; it owns everything shared: navigation, engine, annotation store) and :class:`ClientSession`
the per-browser state that the Annotate tab (:mod:`app.annotate_tab`) builds on (see
:mod:`app.session` for what a tab may use). ``app`` imports ``annotate``, ``scenes`` and
``model``; none of them imports ``app``.
"""

from app.server import AppConfig, Talk2PCApp
from app.session import ClientSession

__all__ = ["AppConfig", "ClientSession", "Talk2PCApp"]
