"""Paths the tests compute, from one place: the repository root and the tests' data folder.

Test modules sit in sub-folders of tests/ that mirror the packages (tests/model/training/, ...);
each takes these constants rather than counting ``Path(__file__).parents``.
"""

from __future__ import annotations

from pathlib import Path

TESTS = Path(__file__).resolve().parent
"""The tests/ folder."""
REPO = TESTS.parent
"""The repository root (the folder holding launch.py)."""
TEST_DATA = TESTS / "data"
"""tests/data/: the pinned reference files (synth pins, decode and equivalence references)."""
