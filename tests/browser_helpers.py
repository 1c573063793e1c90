"""Real-browser helpers shared by the browser tests and the screenshot scripts: where Debian's
Chromium is, the flags it runs with (headless, software rendering), and a page-side check of
viser's scene tree. Not a test module; the ``chromium`` fixture of ``conftest.py`` uses it.
"""

from __future__ import annotations

import shutil
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ARTIFACTS = REPO / "artifacts"
CHROMIUM_CANDIDATES = ("/usr/bin/chromium", "/usr/bin/chromium-browser")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--enable-unsafe-swiftshader",
    "--use-angle=swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
]


def find_chromium() -> str | None:
    """Path of a Chromium executable, or None."""
    for candidate in CHROMIUM_CANDIDATES:
        if Path(candidate).is_file():
            return candidate
    return shutil.which("chromium")


def scene_has(name: str) -> str:
    """A JavaScript predicate: the browser's own scene tree (``window.__viserSceneTree``, a hook
    the viser 1.1.1 client exposes) holds the node ``name``."""
    return (
        "() => window.__viserSceneTree !== undefined && "
        f"Object.keys(window.__viserSceneTree.getState()).includes({name!r})"
    )
