"""What every browser's session shows the same way: :class:`SessionOptions`, and the tabs added
to every panel, :class:`ExtraTab` (their own module so that :mod:`app.session` stays one
screenful of concerns; imported from there as before)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from scenes.frame import Sample


@dataclass(frozen=True)
class SessionOptions:
    """What every session shows the same way.

    Attributes:
        model_note: A warning shown at the top of the panel (None: none).
        score_threshold: The query panel's initial score threshold.
        labelled_boxes: The labelled boxes of a sample's frame (``model.LabelledBoxes``, None
            where it has none); None: the root has no labelled boxes (no "Candidates" control).
    """

    model_note: str | None = None
    score_threshold: float = 0.3
    labelled_boxes: Callable[[Sample], object | None] | None = None


@dataclass(frozen=True)
class ExtraTab:
    """A tab added after Query and View (see :mod:`app.session`).

    Attributes:
        label: The tab's title.
        icon: Its icon (a ``viser.Icon``).
        build: Fills the tab of one browser: ``build(session)`` (an
            :class:`app.session.ClientSession`).
        name: What the tab is called in the message shown when ``build`` fails.
    """

    label: str
    icon: str
    build: Callable[[Any], object]
    name: str = "panel"


__all__ = ["ExtraTab", "SessionOptions"]
