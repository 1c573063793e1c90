"""The Talk2Radar and View-of-Delft formats: a root's layout, reader, writers, sidecars, labels,
point clouds, images, poses, drives, reviews.

It imports ``scenes.geometry`` and ``scenes.utils`` only.
"""
