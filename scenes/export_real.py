"""A synthetic root as the real releases come: ``python -m scenes.export_real --source SYNTH_ROOT
--t2r OUT_T2R --vod OUT_VOD [--splits train val test] [--radar radar|radar_3frames|radar_5frames|both]``.

``SYNTH_ROOT`` is a root written by ``python -m scenes.synth`` (with its ``meta/`` sidecars). The
export writes the same frames twice, each tree as its release has it, so that every path that
trains, evaluates or annotates on real data can be run without the real data:

``OUT_T2R``: a Talk2Radar tree (spec §1.2)
    ``lidar/`` and the radar trees, each with ``ImageSets/`` and
    ``training/{velodyne,calib,label_2,prompt,image_2}``: **one prompt per frame** (the first
    sample of each synthetic world; the world's other prompts are left out and counted), its
    ``label_2`` = that prompt's referents only (the source sample's label file), and no Talk2PC
    file at all: no ``meta/``, no ``sources/``, no manifest.
``OUT_VOD``: a View-of-Delft tree (:mod:`scenes.talk2radar.vod_writer`)
    the same frame ids, ``lidar/`` and the radar trees with ``ImageSets/`` and
    ``training/{velodyne,calib,image_2,label_2}``, no ``prompt/``; ``label_2`` lists every object
    of the frame that View-of-Delft would annotate (within 50 m and in the camera's view) under
    VoD's class names, parked bicycles, racks, mopeds and the riders of cyclists included
    (:mod:`scenes.synth.vod_labels`). VoD withholds its test labels; the export writes them for every
    split, so that grounding over labelled boxes can be measured on a test root.

Both trees carry the lists ``train``, ``val``, ``test`` (those of ``--splits``) and, as VoD,
``train_val`` (train then val) where both are exported.

Radar trees (``--radar``): by default the source's tree (``radar_5frames`` for ``scenes.synth``'s
default 5 scans), hard-linked. ``radar`` (one scan) and ``radar_3frames`` are taken from a source
with more scans by keeping its newest scans (the points whose ``time`` is ``0``, or ``0, -1,
-2``): each accumulated scan is simulated on its own, newest first, so the newest one *is* a
single scan (byte for byte the file ``scenes.synth --radar-scans 1`` writes for the same seed).
``both`` writes ``radar`` and ``radar_5frames``. A tree of more scans than the source has is
refused.

Sensor files and camera images are hard links to the source's (copies across filesystems:
:func:`scenes.utils.durable.link_or_copy`); text files are written atomically. Resumable: a frame whose
label files exist in every tree, with its LiDAR file linked to the source's, is skipped; the
ImageSets lists are written last. Errors are one line, ``error: ...``, exit code 2.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from tqdm import tqdm

from scenes.frame import RootError
from scenes.frame.image import label_image_size
from scenes.frame.kitti import ObjectLabel, label_file_text, read_label_file
from scenes.geometry.calib import read_calib
from scenes.synth.vod_labels import frame_labels, frame_objects
from scenes.talk2radar.layout import (
    CALIB,
    LABEL,
    LIDAR_FOLDER,
    META,
    PROMPT,
    RADAR_FOLDERS,
    SCANS_OF_RADAR_FOLDER,
    SOURCES,
    TRAIN_VAL,
    VELODYNE,
    meta_file,
    sample_dir,
    sample_file,
)
from scenes.talk2radar.pointcloud import RADAR_FEATURES, read_points, write_points
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.vod_writer import VodWriter
from scenes.talk2radar.writer import LABEL_DECIMALS, SampleText, SensorFiles, Talk2RadarWriter
from scenes.utils.cli import command_parser, option, run_command

__all__ = ["RADAR_CHOICES", "SPLITS", "ExportReport", "export", "main", "source_frames"]

SPLITS = ("train", "val", "test")
"""The splits exported by default (the source's lists of these names)."""
RADAR_CHOICES: dict[str, tuple[str, ...]] = {
    "radar": ("radar",),
    "radar_3frames": ("radar_3frames",),
    "radar_5frames": ("radar_5frames",),
    "both": ("radar", "radar_5frames"),
}
"""``--radar`` values and the radar trees each writes."""
TIME = 6
"""Column of a radar point's scan index (``0`` newest, ``-1``, ``-2``, ... older)."""


@dataclass(frozen=True)
class ExportReport:
    """What :func:`export` did.

    Attributes:
        splits: Split name -> exported frame ids (``train_val`` included where written).
        written: Frames written by this run.
        skipped: Frames already complete from an earlier run.
        dropped_prompts: Source samples left out (a world's prompts after its first).
        objects: VoD class -> count of ``label_2`` lines of the exported frames (VoD tree).
        referents: Class -> count of ``label_2`` lines of the Talk2Radar tree.
        radar_folders: The radar trees written.
        seconds: Wall time.
    """

    splits: dict[str, list[str]]
    written: int
    skipped: int
    dropped_prompts: int
    objects: dict[str, int]
    referents: dict[str, int]
    radar_folders: tuple[str, ...]
    seconds: float

    @property
    def frames(self) -> int:
        """Frames exported (each once, whatever the lists)."""
        return self.written + self.skipped


def source_frames(root: Talk2RadarRoot, splits: Sequence[str]) -> tuple[list[tuple[str, str]], int]:
    """``(split, id)`` of the first sample of each synthetic world in the source's lists
    ``splits``, in list order, and the number of samples left out (the worlds' other prompts).

    Raises:
        RootError: a missing list or sidecar (the export needs ``scenes.synth``'s sidecars).
    """
    frames: list[tuple[str, str]] = []
    seen: set[int] = set()
    dropped = 0
    for split in splits:
        for sid in root.ids(split):
            meta = root.source_meta(sid)
            if meta.world_id >= 0 and meta.world_id in seen:
                dropped += 1
                continue
            seen.add(meta.world_id)
            frames.append((split, sid))
    return frames, dropped


def _check_output(path: Path, source: Path, forbidden: Sequence[str]) -> None:
    """Refuse an output that is the source, or holds something an export did not write."""
    if path.resolve() == source.resolve():
        raise RootError(f"{path}: is the source root; choose another output folder")
    if not path.exists():
        return
    if not path.is_dir():
        raise RootError(f"{path}: exists and is not a folder")
    names = {p.name for p in path.iterdir()}
    if names and (LIDAR_FOLDER not in names or names & set(forbidden)):
        raise RootError(
            f"{path}: exists and is neither empty nor an earlier export (it holds "
            f"{', '.join(sorted(names)[:4])}); choose another output folder"
        )


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def export(
    source: str | Path,
    t2r: str | Path | None,
    vod: str | Path | None,
    splits: Sequence[str] = SPLITS,
    radar: str | None = None,
    progress: bool = False,
) -> ExportReport:
    """Write the real-format trees of the synthetic root ``source`` (see the module docstring).

    Args:
        t2r, vod: Output folders (new, empty, or an earlier export to complete); None writes
            none of that tree (at least one is needed).
        splits: Source lists to export.
        radar: A key of :data:`RADAR_CHOICES`, or None for the source's radar tree.

    Raises:
        RootError: a bad source or output folder, or an impossible radar tree.
        ValueError: a malformed file of the source (named).
    """
    start = time.perf_counter()
    source = Path(source)
    if t2r is None and vod is None:
        raise RootError("nothing to write: give --t2r, --vod or both")
    if t2r is not None and vod is not None and Path(t2r).resolve() == Path(vod).resolve():
        raise RootError(f"{t2r}: --t2r and --vod must be different folders")
    root = Talk2RadarRoot(source, radar="auto")
    if root.radar_dir is None or root.radar_folder is None:
        raise RootError(f"{source}: no radar tree ({', '.join(RADAR_FOLDERS)})")
    source_scans = SCANS_OF_RADAR_FOLDER[root.radar_folder]
    folders = RADAR_CHOICES[radar] if radar is not None else (root.radar_folder,)
    for folder in folders:
        if SCANS_OF_RADAR_FOLDER[folder] > source_scans:
            raise RootError(
                f"{source}: --radar {folder} needs {SCANS_OF_RADAR_FOLDER[folder]} radar scans; "
                f"the source has {source_scans} ({root.radar_folder}/)"
            )
    if t2r is not None:
        _check_output(Path(t2r), source, (META, SOURCES))
    if vod is not None:
        _check_output(Path(vod), source, (META, SOURCES))
        if sample_dir(Path(vod) / LIDAR_FOLDER, PROMPT).exists():
            raise RootError(f"{vod}: holds prompts; not a View-of-Delft export")
    frames, dropped = source_frames(root, splits)
    if not frames:
        raise RootError(f"{source}: its lists {list(splits)} hold no sample")

    outputs = _Outputs(
        VodWriter(vod, folders) if vod is not None else None,
        tuple(Talk2RadarWriter(t2r, f) for f in folders) if t2r is not None else (),
        source_scans,
    )
    objects: Counter[str] = Counter()
    referents: Counter[str] = Counter()
    written = skipped = 0
    for _split, sid in tqdm(frames, desc="export", unit="frame", disable=not progress):
        files = _source_files(root, sid)
        meta = root.load_meta(sid)
        assert meta is not None  # source_frames checked it
        calib = read_calib(files.lidar_calib)
        vod_objects = frame_objects(meta, str(meta_file(root.path, sid)))
        labels = frame_labels(vod_objects, calib, label_image_size(files.image))
        referred = read_label_file(sample_file(root.lidar_dir, LABEL, sid))
        objects.update(lab.name for lab in labels)
        referents.update(lab.name for lab in referred)
        if outputs.complete(sid, files.lidar_bin):
            skipped += 1
            continue
        prompt = root.load_prompt(sid)
        if prompt is None:
            raise RootError(f"{root.path}: has no prompt folder; not a root of scenes.synth")
        text = SampleText(label_file_text(referred, LABEL_DECIMALS), prompt + "\n")
        outputs.write(sid, files, text, labels)
        written += 1

    lists = {split: [sid for s, sid in frames if s == split] for split in splits}
    if "train" in lists and "val" in lists:
        lists[TRAIN_VAL] = lists["train"] + lists["val"]
    outputs.write_image_sets(lists)
    return ExportReport(
        splits=lists,
        written=written,
        skipped=skipped,
        dropped_prompts=dropped,
        objects=dict(sorted(objects.items())),
        referents=dict(sorted(referents.items())),
        radar_folders=folders,
        seconds=time.perf_counter() - start,
    )


def _source_files(root: Talk2RadarRoot, sid: str) -> SensorFiles:
    """The sensor files and camera image of source sample ``sid``."""
    assert root.radar_dir is not None  # export checked it
    return SensorFiles(
        folder=root.lidar_dir,
        lidar_bin=sample_file(root.lidar_dir, VELODYNE, sid),
        radar_bin=sample_file(root.radar_dir, VELODYNE, sid),
        lidar_calib=sample_file(root.lidar_dir, CALIB, sid),
        radar_calib=sample_file(root.radar_dir, CALIB, sid),
        image=root.image_path(sid),
    )


@dataclass(frozen=True)
class _Outputs:
    """The trees one export writes: the View-of-Delft tree (or None) and one Talk2Radar writer
    per radar tree (none without ``--t2r``; they share the LiDAR tree)."""

    vod: VodWriter | None
    t2r: tuple[Talk2RadarWriter, ...]
    source_scans: int

    @property
    def folders(self) -> tuple[str, ...]:
        if self.vod is not None:
            return self.vod.radar_folders
        return tuple(w.radar_folder for w in self.t2r)

    def complete(self, sid: str, lidar_bin: Path) -> bool:
        """Whether frame ``sid`` is complete from an earlier run: its label files exist in every
        tree (they are written last) and its LiDAR files are links to ``lidar_bin``."""
        labels = [] if self.vod is None else self.vod.label_files(sid)
        lidar = [] if self.vod is None else [sample_file(self.vod.lidar_tree, VELODYNE, sid)]
        for writer in self.t2r:
            labels += [sample_file(tree, LABEL, sid) for tree in writer.trees]
            lidar.append(sample_file(writer.trees[0], VELODYNE, sid))
        return all(p.is_file() for p in labels) and all(_same_file(p, lidar_bin) for p in lidar)

    def write(
        self, sid: str, files: SensorFiles, text: SampleText, labels: Sequence[ObjectLabel]
    ) -> None:
        """Write frame ``sid`` into every tree: sensor links (radar cut to each tree's scans),
        then the Talk2Radar text files and the View-of-Delft labels."""
        for k, folder in enumerate(self.folders):
            radar_files = self._radar_files(files, sid, folder, k)
            if self.vod is not None:
                self.vod.link_sensors(sid, radar_files, folder)
            if self.t2r:
                self.t2r[k].write_sample_text(sid, radar_files, text)
        if self.vod is not None:
            self.vod.write_labels(sid, labels)

    def write_image_sets(self, lists: dict[str, list[str]]) -> None:
        if self.vod is not None:
            self.vod.write_image_sets(lists)
        for writer in self.t2r:
            writer.write_image_sets(lists)

    def _radar_files(self, files: SensorFiles, sid: str, folder: str, k: int) -> SensorFiles:
        """``files`` with the radar points of tree ``folder``: the source's file where it has
        that many scans, else its newest scans, written once into the first output (and linked
        from there into the other)."""
        scans = SCANS_OF_RADAR_FOLDER[folder]
        if scans == self.source_scans:
            return files
        points = read_points(files.radar_bin, RADAR_FEATURES)
        points = points[points[:, TIME] > -scans + 0.5]
        if self.vod is not None:
            path = self.vod.write_radar(sid, folder, points)
        else:
            path = sample_file(self.t2r[k].trees[1], VELODYNE, sid)
            write_points(path, points)
        return replace(files, radar_bin=path)


@dataclass(frozen=True, kw_only=True)
class ExportCommand:
    """The flags of ``python -m scenes.export_real`` (the arguments of :func:`export`)."""

    source: Path = option(help="a root written by scenes.synth")
    t2r: Path | None = option(None, help="output folder of the Talk2Radar tree")
    vod: Path | None = option(None, help="output folder of the View-of-Delft tree")
    splits: tuple[str, ...] = option(
        SPLITS,
        nargs="+",
        metavar="SPLIT",
        help="source lists to export (default: %(default)s)",
    )
    radar: str | None = option(
        None,
        choices=sorted(RADAR_CHOICES),
        help="radar trees to write (default: the source's; both = radar and radar_5frames)",
    )
    quiet: bool = option(False, help="no progress bar")


def _parser() -> argparse.ArgumentParser:
    return command_parser(
        "python -m scenes.export_real",
        "Write a synthetic root (scenes.synth) as the real releases come: a Talk2Radar tree (one "
        "prompt per frame, label_2 = its referents, no sidecar) and a View-of-Delft tree (label_2 "
        "= every annotated object of the frame, VoD class names).",
        ExportCommand,
    )


def run(args: ExportCommand) -> int:
    """Export as ``args`` says and print what was written (errors raise)."""
    report = export(
        args.source, args.t2r, args.vod, args.splits, args.radar, progress=not args.quiet
    )
    counts = ", ".join(f"{k} {len(v)}" for k, v in report.splits.items())
    objects = ", ".join(f"{k} {v}" for k, v in report.objects.items())
    print(
        f"{report.frames} frames ({report.written} written, {report.skipped} already complete) "
        f"in {report.seconds:.1f} s; lists: {counts}; radar trees: {', '.join(report.radar_folders)}"
        f"; {report.dropped_prompts} further prompts of the same worlds left out "
        f"(one prompt per frame)"
    )
    if args.vod is not None:
        print(f"{args.vod}: View-of-Delft labels: {objects}")
    if args.t2r is not None:
        referents = ", ".join(f"{k} {v}" for k, v in report.referents.items())
        print(f"{args.t2r}: Talk2Radar referents: {referents}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m scenes.export_real``; a bad root is one ``error:`` line, exit status 2."""
    return run_command(_parser(), ExportCommand, run, argv)


if __name__ == "__main__":
    sys.exit(main())
