"""The error of the dataset layer, at the bottom of scenes/ so that every reader raises it:
:class:`RootError` (re-exported by :mod:`scenes.frame`)."""

from __future__ import annotations


class RootError(ValueError):
    """A dataset root is incomplete or malformed (any family); the message names the file."""
