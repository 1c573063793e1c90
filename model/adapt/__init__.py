"""Adaptation of a checkpoint's detector to a new sensor set-up from unlabelled frames
(``python -m model.adapt --data ROOT --init CKPT --out RUN``; issue 38, item 3).

Self-training after ST3D (Yang et al., CVPR 2021): confident detections become pseudo-labels
under per-class thresholds, remembered and merged across rounds, trained on under random views of
the cloud, with a curriculum that admits less certain and more distant boxes as the rounds go.
The pieces: :mod:`~model.adapt.config` (the flags and the curriculum), :mod:`~model.adapt.frames`
(the root's sensor files, never its labels or sidecars), :mod:`~model.adapt.pseudo` (selection,
memory, partition), :mod:`~model.adapt.augment` (the views), :mod:`~model.adapt.state` (the
resumable state and the checkpoints' lineage) and :mod:`~model.adapt.run` (the rounds).
"""
