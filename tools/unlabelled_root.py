"""``python -m tools.unlabelled_root --source ROOT --out OUT``: a root's sensor files only, as an
unlabelled recording comes (the input of ``python -m model.adapt``; issue 38's measure adapts on
such a copy of a labelled root).

Copied (hard links where possible, :func:`scenes.utils.durable.link_or_copy`): the LiDAR tree's
``velodyne/``, ``calib/`` and ``image_2/`` and each radar tree's ``velodyne/`` and ``calib/``.
Left out: ``label_2/``, ``prompt/``, ``ImageSets/``, ``meta/``, poses, manifests and everything
else. Errors are one line (``error: ...``, exit 2).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from scenes.frame import RootError
from scenes.talk2radar.layout import (
    CALIB,
    IMAGE,
    LIDAR_FOLDER,
    VELODYNE,
    radar_folders_in,
    sample_dir,
)
from scenes.utils.cli import add_options, error_line, from_args, option
from scenes.utils.durable import link_or_copy

SENSOR_FOLDERS = {LIDAR_FOLDER: (VELODYNE, CALIB, IMAGE)}
"""The folders a LiDAR tree contributes; each radar tree contributes ``velodyne`` and ``calib``."""


@dataclass(frozen=True)
class UnlabelledRootCommand:
    """The command's flags."""

    source: Path = option(help="a Talk2Radar or View-of-Delft root")
    out: Path = option(help="the sensor-only root to write")


def sensor_only_copy(source: str | Path, out: str | Path) -> int:
    """Copy ``source``'s sensor files into ``out`` (module docstring); returns the files copied.

    Raises:
        RootError: ``source`` has no ``lidar/`` tree or no LiDAR point file.
    """
    source, out = Path(source), Path(out)
    if not (source / LIDAR_FOLDER).is_dir():
        raise RootError(f"{source}: not a Talk2Radar root (no {LIDAR_FOLDER}/ folder)")
    trees = {LIDAR_FOLDER: SENSOR_FOLDERS[LIDAR_FOLDER]}
    trees.update({radar: (VELODYNE, CALIB) for radar in radar_folders_in(source)})
    count = 0
    for tree, folders in trees.items():
        for folder in folders:
            src_dir = sample_dir(source / tree, folder)
            if not src_dir.is_dir():
                continue
            for path in sorted(src_dir.iterdir()):
                if path.is_file():
                    link_or_copy(path, sample_dir(out / tree, folder) / path.name)
                    count += 1
    if not sample_dir(out / LIDAR_FOLDER, VELODYNE).is_dir():
        raise RootError(f"{sample_dir(source / LIDAR_FOLDER, VELODYNE)}: no LiDAR point files")
    return count


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m tools.unlabelled_root",
        description="Copy a root's sensor files only (no labels, prompts or sidecars).",
    )
    add_options(parser, UnlabelledRootCommand)
    return parser


def main(argv: list[str] | None = None) -> int:
    cmd = from_args(UnlabelledRootCommand, build_parser().parse_args(argv))
    try:
        count = sensor_only_copy(cmd.source, cmd.out)
    except (RootError, OSError) as exc:
        print(f"error: {error_line(exc)}", file=sys.stderr)
        return 2
    print(f"{cmd.out}: {count} sensor files of {cmd.source} (no labels, prompts or sidecars)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
