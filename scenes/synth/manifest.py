"""The generator's manifest, ``synth_manifest.jsonl`` at a root's top: its name, and what a
reader may learn from it without importing the simulation (:func:`manifest_classes`).

Its first line is ``{"settings": SynthSettings.key()}`` (``"classes"`` in it when not ``vod``),
each further line a world entry (:mod:`scenes.synth.generate` writes and resumes it).
"""

from __future__ import annotations

import json
from pathlib import Path

MANIFEST = "synth_manifest.jsonl"
"""The manifest's file name at the root's top."""


def manifest_classes(root: str | Path) -> str | None:
    """The class set a synthetic root was generated with (``python -m scenes.synth --classes``:
    ``vod`` when its settings line names none), or None when ``root`` holds no manifest.

    Raises:
        ValueError: the manifest's first line is not a settings line (one line naming the file).
    """
    path = Path(root) / MANIFEST
    if not path.is_file():
        return None
    with path.open(encoding="utf-8") as f:
        first = f.readline()
    try:
        settings = json.loads(first)["settings"]
        classes = settings.get("classes", "vod")
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"{path}:1: not the generator's settings line ({exc})") from exc
    if not isinstance(classes, str):
        raise ValueError(f"{path}:1: field 'settings.classes': expected a name, got {classes!r}")
    return classes


__all__ = ["MANIFEST", "manifest_classes"]
