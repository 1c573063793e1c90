"""A synthetic root as nuScenes and Talk2Car come: ``python -m scenes.export_nuscenes --source
SYNTH --out NUSC [--splits train val test] [--seed N] [--version v1.0-trainval]``.

``SYNTH`` is a root written by ``python -m scenes.synth`` (with its ``meta/`` sidecars: every
actor of a frame, each sample's prompt and referents). Its samples are grouped into frames (the
samples sharing sensor files) and worlds; each frame becomes one nuScenes sample, each world one
scene, and each single-referent prompt one Talk2Car command in ``NUSC/commands/{split}_commands.json``
(the split the source's list names). What the files hold, frames and poses:
:mod:`scenes.nuscenes.export`. The command's sentence is the prompt phrased as a driving command
(``--phrasing``, default ``all``: an instruction of any of the generator's command templates,
:func:`scenes.language.prompts.commands.as_command`, wrapped around the description, drawn from
``--seed``); ``--phrasing none`` keeps the prompt as the generator wrote it.
``--out`` is new, empty or an earlier export of this command (:func:`export`): no other folder is
written into, and only files an export wrote are ever replaced or removed.
Errors are one line, ``error: ...``, exit code 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.geometry.actors import Actor
from scenes.language.prompts.commands import as_command
from scenes.language.prompts.phrasing.split import PHRASINGS
from scenes.nuscenes.export import (
    ExportReport,
    Sentence,
    SourceFrame,
    SourcePrompt,
    export_frames,
)
from scenes.synth.radar import RadarConfig
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.utils.cli import command_parser, option, run_command
from scenes.utils.owned import owned_output

__all__ = ["SPLITS", "ExportNuScenesCommand", "export", "main", "source_frames"]

SPLITS = ("train", "val", "test")
"""The source lists exported by default."""
WRITER = "scenes.export_nuscenes"
"""This command's name in the marker of its outputs (:mod:`scenes.utils.owned`)."""


def source_frames(root: Talk2RadarRoot, splits: Sequence[str]) -> list[SourceFrame]:
    """The frames of a synthetic root's lists ``splits``, grouped by world (first seen first),
    each with every prompt made on it.

    Raises:
        RootError: a missing list or sidecar (the export needs scenes.synth's sidecars).
    """
    frames: dict[tuple, dict] = {}
    for split in splits:
        for sid in root.ids(split):
            meta = root.source_meta(sid)
            key = root.frame_key(sid)
            prompt = SourcePrompt(sid, split, root.load_prompt(sid) or "", meta.referent_ids)
            if key in frames:
                frames[key]["prompts"].append(prompt)
                continue
            sample = root.load(sid)
            frames[key] = {
                "world": meta.world_id if meta.world_id >= 0 else len(frames),
                "lidar": sample.lidar,
                "radar": sample.radar,
                "actors": meta.actors,
                "calib": sample.calib,
                "image_path": sample.image_path,
                "image_size": sample.image_size,
                "weather": meta.weather,
                "ego_speed": meta.ego_velocity,
                "prompts": [prompt],
            }
    order = {}
    for f in frames.values():
        order.setdefault(f["world"], len(order))
    out = [SourceFrame(**{**f, "prompts": tuple(f["prompts"])}) for f in frames.values()]
    return sorted(out, key=lambda f: order[f.world])


def export(
    source: str | Path,
    out: str | Path,
    splits: Sequence[str] = SPLITS,
    seed: int = 0,
    version: str = "v1.0-trainval",
    phrasing: str | None = "all",
) -> ExportReport:
    """Write the synthetic root ``source`` as a nuScenes root with Talk2Car commands at ``out``.
    ``phrasing``: the command phrasing stream of the sentences, None for the prompts as written
    (:func:`scenes.nuscenes.export.export_frames`).

    ``out`` must be new, empty, or an earlier export of this command (recognised by the marker
    it left, :data:`scenes.utils.owned.MARKER`), and apart from ``source`` (neither it, inside it
    nor containing it). The root is written into a staging folder beside ``out`` and installed
    when complete (:func:`scenes.utils.owned.owned_output`): an earlier export's files are
    replaced, any other file in ``out`` is kept, and a failed export leaves ``out`` as it was.

    Raises:
        RootError: a bad source.
        scenes.utils.owned.FolderError: a refused output folder (one line naming it).
        ValueError: a malformed file of the source (named).
    """
    sentence = None if phrasing is None else command_sentence(phrasing)
    source, out = Path(source), Path(out)
    root = Talk2RadarRoot(source, radar="auto")
    with owned_output(out, WRITER, {"the source root": source}) as staging:
        frames = source_frames(root, splits)
        return export_frames(
            frames,
            staging,
            seed=seed,
            version=version,
            scan_period=RadarConfig().scan_period,
            sentence=sentence,
        )


def command_sentence(phrasing: str) -> Sentence:
    """The sentence of a command: a single-referent prompt's text wrapped into a driving
    instruction (:func:`scenes.language.prompts.commands.as_command`, with the referent's class
    and motion) of the ``phrasing`` stream (``train``, ``heldout`` or ``all``), drawn from the key
    the export passes (its seed, the frame and the prompt), so deterministic by ``--seed``.

    Raises:
        ValueError: an unknown ``phrasing``.
    """
    if phrasing not in PHRASINGS:
        raise ValueError(
            f"phrasing must be one of {', '.join(PHRASINGS)} or None, got {phrasing!r}"
        )

    def sentence(text: str, actor: Actor, key: tuple[int, ...]) -> str:
        rng = np.random.default_rng((*key, 41))
        return as_command(text, rng, phrasing, cls=actor.cls, moving=actor.is_moving)

    return sentence


@dataclass(frozen=True)
class ExportNuScenesCommand:
    """The flags of ``python -m scenes.export_nuscenes`` (the arguments of :func:`export`)."""

    source: Path = option(help="a root written by scenes.synth")
    out: Path = option(help="output folder of the nuScenes root (commands/ inside)")
    splits: tuple[str, ...] = option(
        SPLITS, nargs="+", metavar="SPLIT", help="source lists to export (default: %(default)s)"
    )
    seed: int = option(0, help="seed of the random global poses (default %(default)s)")
    version: str = option("v1.0-trainval", help="version folder name (default %(default)s)")
    phrasing: str = option(
        "all",
        choices=(*PHRASINGS, "none"),
        help="the commands' wording: each single-referent prompt wrapped into a driving command "
        "of this phrasing stream of the generator's templates (train, heldout, all), or none: the "
        "prompt as written (default %(default)s)",
    )


def _parser() -> argparse.ArgumentParser:
    return command_parser(
        "python -m scenes.export_nuscenes",
        "Write a synthetic root (scenes.synth) as nuScenes and Talk2Car come: the 13 tables, "
        "LIDAR_TOP and five radar files in their own frames, CAM_FRONT images and "
        "commands/{split}_commands.json from the single-referent prompts.",
        ExportNuScenesCommand,
    )


build_parser = _parser


def run(args: ExportNuScenesCommand) -> int:
    """Export as ``args`` says and print what was written (errors raise)."""
    start = time.perf_counter()
    phrasing = None if args.phrasing == "none" else args.phrasing
    report = export(args.source, args.out, args.splits, args.seed, args.version, phrasing)
    print(
        f"Wrote {args.out} in {time.perf_counter() - start:.1f} s: {report.summary()}", flush=True
    )
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m scenes.export_nuscenes``; a bad root is one ``error:`` line, exit status 2."""
    return run_command(_parser(), ExportNuScenesCommand, run, argv)


if __name__ == "__main__":
    sys.exit(main())
