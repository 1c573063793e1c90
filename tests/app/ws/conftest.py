"""Fixtures of the websocket tests of a served nuScenes root (module-scoped: one app a module)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def nusc_app(serve_nuscenes):
    """The nuScenes root with its commands, served on its train split."""
    with serve_nuscenes("train") as app:
        yield app


@pytest.fixture(scope="module")
def nusc_all(serve_nuscenes):
    """The nuScenes root with its commands, served on every sample (split ``all``)."""
    with serve_nuscenes("all") as app:
        yield app
