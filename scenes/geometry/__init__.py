"""Shared geometry and types of a frame: actors and classes, boxes, calibration, projection into the
camera.

The bottom room of ``scenes`` but for ``scenes.utils``.
"""
