"""The dataset layer's neutral frame (bottom of the dataset layer; every family implements it).

- :class:`Sample` (:mod:`scenes.frame.sample`): one frame's sensors in the LiDAR frame, one prompt
  and the boxes it refers to; :class:`RootError` (:mod:`scenes.utils.errors`): a root that cannot
  be read, the message naming the file.
- :class:`FrameSource` (:mod:`scenes.frame.source`): what a family's reader offers (``path``,
  ``splits()``, ``ids(split)``, ``load(id) -> Sample``, ``frame_key(id)``).
- What a frame carries, whatever its family: the camera image (:mod:`scenes.frame.image`), the
  object label lines (:mod:`scenes.frame.kitti`, KITTI's format, as View-of-Delft and the
  Talk2Radar pairs write them) and Talk2PC's sidecar (:mod:`scenes.frame.sample_meta`).

Which family a root is, is decided once, by :func:`scenes.datasets.source.open_source`.
"""

from scenes.frame.sample import Sample
from scenes.frame.source import FrameSource
from scenes.utils.errors import RootError

__all__ = ["FrameSource", "RootError", "Sample"]
