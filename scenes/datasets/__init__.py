"""The torch training datasets and their augmentations.

The top room of ``scenes``.
"""
