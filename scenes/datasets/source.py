"""Which dataset family a root is, decided once: :func:`root_family` and :func:`open_source`.

Two families are read today: a Talk2Radar root or a View-of-Delft release
(:class:`scenes.talk2radar.root.Talk2RadarRoot`), and a nuScenes root as the release comes with
its Talk2Car command folder (:class:`scenes.nuscenes.source.NuScenesSource`). A nuScenes root is
a folder holding a ``v1.0-*`` table folder (:func:`is_nuscenes_root`); a Talk2Radar root never
holds one. The rule "``--talk2car`` goes with a nuScenes root", and its messages, live here and
nowhere else: the app's launcher, training and evaluation all ask :func:`root_family`. The two
readers are re-exported here: the packages above scenes/ reach a family through this module.

A third family (Waymo, TruckScenes, K-Radar) is one package whose reader implements
:class:`scenes.frame.FrameSource`, one value of :data:`Family` and one branch of each function
here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from scenes.frame import FrameSource
from scenes.geometry.classes import VOD, ClassSet
from scenes.nuscenes.source import NuScenesSource
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.utils.errors import RootError

__all__ = [
    "NUSCENES",
    "TALK2RADAR",
    "Family",
    "NuScenesSource",
    "Talk2RadarRoot",
    "is_nuscenes_root",
    "open_source",
    "root_family",
]

Family = Literal["talk2radar", "nuscenes"]
TALK2RADAR: Family = "talk2radar"
NUSCENES: Family = "nuscenes"

VERSION_PREFIX = "v1.0-"
"""A nuScenes root holds one folder named ``v1.0-<version>`` (trainval, mini, test) of tables."""


def is_nuscenes_root(path: str | Path) -> bool:
    """Whether ``path`` is a folder holding a ``v1.0-*`` table folder (a nuScenes root as the
    release comes); a Talk2Radar root never does."""
    folder = Path(path)
    if not folder.is_dir():
        return False
    return any(p.is_dir() and p.name.startswith(VERSION_PREFIX) for p in folder.iterdir())


def root_family(
    path: str | Path, talk2car: str | Path | None = None, commands_required: bool = False
) -> Family:
    """The family of the root at ``path`` given with ``--talk2car`` (None: not given).

    Args:
        path: The ``--data`` root.
        talk2car: The Talk2Car command folder given with it, or None.
        commands_required: Whether a nuScenes root must come with its command folder (training
            and evaluation ground its commands; the app also serves a nuScenes root without).

    Raises:
        RootError: a command folder with a root that is not a nuScenes root, or (with
            ``commands_required``) a nuScenes root without one; one line naming both flags.
    """
    nuscenes = is_nuscenes_root(path)
    if talk2car is not None and not nuscenes:
        raise RootError(
            f"--talk2car {talk2car} goes with a nuScenes root as --data (a folder holding "
            f"{VERSION_PREFIX}*/); {path} is not a nuScenes root"
        )
    if nuscenes and talk2car is None and commands_required:
        raise RootError(
            f"--data {path} is a nuScenes root (it holds a {VERSION_PREFIX}* folder): give its "
            "Talk2Car command folder with --talk2car DIR (the folder holding "
            "{split}_commands.json)"
        )
    return NUSCENES if nuscenes else TALK2RADAR


def open_source(
    path: str | Path,
    talk2car: str | Path | None = None,
    classes: ClassSet = VOD,
    radar: str | None = "auto",
    sidecar: bool = True,
) -> FrameSource:
    """The reader of the root at ``path``, of its family (:func:`root_family`).

    Args:
        path: The root.
        talk2car: A nuScenes root's Talk2Car command folder (None: its samples without commands).
        classes: The class set labels are read into.
        radar: A Talk2Radar root's radar tree (:class:`~scenes.talk2radar.root.Talk2RadarRoot`).
        sidecar: Whether a Talk2Radar root's ``meta/`` sidecars are read.

    Raises:
        RootError: :func:`root_family`'s, or a root its reader refuses (one line naming the file;
            a nuScenes table or command file error included).
    """
    if root_family(path, talk2car) == NUSCENES:
        return NuScenesSource(path, talk2car, classes)
    return Talk2RadarRoot(path, radar=radar, sidecar=sidecar, classes=classes)
