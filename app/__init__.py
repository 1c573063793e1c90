"""The viser front: scene rendering, colour maps, the query panel, navigation.

``python launch.py`` serves it; :class:`Talk2PCApp` is the app object (start / stop, port 0 for
tests) and :class:`ClientSession` the per-browser state that the annotation mode builds on (see
:mod:`app.session` for its extension point). ``app`` imports ``scenes`` and ``model``-like objects;
neither imports ``app``.
"""

from app.server import AppConfig, Talk2PCApp
from app.session import ClientSession

__all__ = ["AppConfig", "ClientSession", "Talk2PCApp"]
