"""Serve the Talk2PC app: ``python launch.py [--data ROOT] [--checkpoint PATH] [--host 127.0.0.1]
[--port 8080] [--device cpu|cuda] [--split SPLIT] [--threads 1] [--pairs DIR] [--talk2car CMDS]``.

- No ``--data``: a small deterministic synthetic set is generated once into ``data/default``
  (``python -m scenes.synth --out data/default --frames 60 --seed 0``, about 10 s) and served;
  later runs reuse it. A generation interrupted half-way resumes where it stopped.
- No ``--checkpoint``: the bundled ``checkpoints/tpcnet-small.pt``. Where it does not exist yet, a
  freshly initialised small model is served with a warning in the log and in every browser panel
  ("untrained model: boxes are meaningless").
- ``--data`` may be a Talk2Radar root or a View-of-Delft root as released (``lidar/`` and
  ``radar/``, ``radar_3frames/`` or ``radar_5frames/``, no ``prompt/`` folder, ImageSets in the
  LiDAR tree). Without ``--split`` the first of ``test``, ``val``, ``train`` (then the others) whose
  frames all have their files is served (VoD's ``test`` frames are not in ``training/``).
- Annotation saves pairs into ``--pairs DIR`` (created by the first save); by default into the
  served root when it has prompts (a Talk2Radar root). A root without prompts (a release as it
  comes) is never written into or beside: without ``--pairs`` the Annotate tab does not save and
  suggests ``--pairs <ROOT>-talk2radar`` (:func:`app.serving.served.default_pairs_root`). Serving writes
  nothing until the first save.
- ``--data`` may be a nuScenes root as released (``v1.0-*/``, ``samples/``, ``sweeps/``) with
  ``--talk2car CMDS`` (the folder holding Talk2Car's ``{split}_commands.json``): every sample
  (split ``all``) or a command file's samples (``--split val``) with their commands listed; pairs
  annotated there are Talk2Car commands saved into ``--pairs DIR`` (``DIR/commands/``), and nowhere
  without it (docs/TALK2CAR.md, section 9).
- A root without an ``ImageSets`` folder (the View-of-Delft devkit's example set) serves every
  frame of ``lidar/training/velodyne/`` (split ``all``, with a notice).
- A ``--checkpoint`` or ``--data`` that is missing or invalid, an unknown split, an ImageSets
  folder without lists, a split listing frames whose sensor, calib or label files are missing (the
  message names the first such file), a split where no frame loads, ``--device cuda`` without CUDA, a ``--port`` outside 0..65535, a ``--host`` that is
  not an address of this machine, or a server that does not listen within 20 s: a one-line error
  on stderr and exit code 2, within seconds (the host and port are checked before anything else).

The URL is printed once the server listens; Ctrl-C (or SIGTERM) stops it cleanly (exit code 0).

Roots are reached through the dataset layer (:mod:`scenes.datasets.source`); which split of a
Talk2Radar root can be served is that reader's knowledge of its layout, so the split checks are
:mod:`scenes.talk2radar.splits`' (the one family module imported here).
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from scenes.utils.cli import add_options, from_args, option, show_warnings_as_lines

if TYPE_CHECKING:
    from model import TPCNet
    from scenes.datasets.source import NuScenesSource, Talk2RadarRoot

REPO = Path(__file__).resolve().parent
DEFAULT_DATA = REPO / "data" / "default"
DEFAULT_FRAMES = 60
DEFAULT_SEED = 0
COMPLETE_MARKER = ".talk2pc-complete"
"""Written into ``data/default`` once the synthetic set is fully generated."""

UNTRAINED_NOTE = "untrained model: boxes are meaningless"

log = logging.getLogger("talk2pc")


class LaunchError(Exception):
    """A user error: bad flags, a missing or invalid file. Exit code 2."""


@dataclass(frozen=True, kw_only=True)
class LaunchConfig:
    """The flags of ``python launch.py`` that are not the app's (``--host``, ``--port``,
    ``--pairs`` and ``--scene-labels`` are :class:`app.server.AppConfig`'s fields).

    Attributes:
        data: The served root (None: the default synthetic set, :func:`ensure_default_data`).
        checkpoint: The served checkpoint (None: the bundled one of the root's class set,
            :func:`root_classes`: ``checkpoints/tpcnet-nuscenes.pt`` on a nuScenes root or a
            ``--classes nuscenes`` synthetic root, ``model.DEFAULT_CHECKPOINT`` otherwise).
        device: The model's device.
        split: The ImageSets split served (None: :func:`choose_split`'s choice; on a nuScenes
            root ``all`` or a command file's split, None: ``all``).
        threads: torch's CPU threads per model call.
    """

    data: Path | None = option(
        None,
        help="a Talk2Radar root, a View-of-Delft release or a nuScenes root (with --talk2car) "
        f"(default: synthetic scenes generated into {DEFAULT_DATA})",
    )
    checkpoint: Path | None = option(
        None,
        help="a TPCNet checkpoint (default: the bundled one of the root's class set: "
        "checkpoints/tpcnet-nuscenes.pt on a nuScenes root or a root generated with --classes "
        "nuscenes, checkpoints/tpcnet-small.pt otherwise)",
    )
    device: Literal["cpu", "cuda"] = option("cpu", help="model device")
    split: str | None = option(
        None,
        help="ImageSets split to browse (default: the first of test, val, train whose frames "
        "all have their files)",
    )
    threads: int = option(
        1,
        help="CPU threads per model call (default %(default)s: on a small shared machine, torch's "
        "multi-threaded kernels slow down badly once the cores are busy)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``python launch.py``: :class:`LaunchConfig`'s and the command-line fields of
    :class:`app.server.AppConfig` (imports the app)."""
    from app.server import AppConfig

    p = argparse.ArgumentParser(
        prog="python launch.py",
        description="Serve the Talk2PC viser app: type a sentence, see the referred objects boxed.",
    )
    add_options(p, LaunchConfig, only=("data", "checkpoint"))
    add_options(p, AppConfig, only=("host", "port"))
    add_options(p, LaunchConfig, only=("device", "split"))
    add_options(p, AppConfig, only=("pairs_root", "scene_labels", "talk2car"))
    add_options(p, LaunchConfig, only=("threads",))
    return p


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The flags of both dataclasses (:func:`build_parser`); usage errors exit 2."""
    return build_parser().parse_args(argv)


def ensure_default_data(
    out: Path = DEFAULT_DATA, frames: int = DEFAULT_FRAMES, seed: int = DEFAULT_SEED
) -> Path:
    """Generate the default synthetic root once (skipped when the completion marker exists)."""
    if (out / COMPLETE_MARKER).is_file():
        return out
    print(f"Generating {frames} synthetic scenes into {out} (once)...", flush=True)
    cmd = [
        sys.executable,
        "-m",
        "scenes.synth",
        "--out",
        str(out),
        "--frames",
        str(frames),
        "--seed",
        str(seed),
    ]
    result = subprocess.run(cmd, cwd=REPO, check=False)
    if result.returncode != 0:
        raise LaunchError(
            f"generating the synthetic scenes failed ({' '.join(cmd[1:])} exited with "
            f"{result.returncode})"
        )
    from scenes.utils.durable import atomic_write_text

    atomic_write_text(out / COMPLETE_MARKER, f"frames={frames} seed={seed}\n")
    return out


def open_root(path: Path, split: str | None) -> Talk2RadarRoot:
    """Open a root and check ``split`` (None: only that the root has a split list); the checks
    are the reader's (:mod:`scenes.talk2radar.splits`).

    Raises:
        LaunchError: not a root, an ImageSets folder without lists, an unknown or empty split, or a split listing
            frames whose files are missing (the message names the first such file).
    """
    from scenes.datasets.source import Talk2RadarRoot
    from scenes.frame import RootError
    from scenes.talk2radar.splits import no_split_lists, split_problem

    if not path.is_dir():
        raise LaunchError(f"--data {path}: no such folder")
    try:
        root = Talk2RadarRoot(path)
        problem = no_split_lists(root)
    except RootError as exc:
        raise LaunchError(str(exc)) from exc
    if problem is None and split is not None:
        problem = split_problem(root, split)
    if problem is not None:
        raise LaunchError(problem)
    return root


def choose_split(root: Talk2RadarRoot, split: str | None) -> str:
    """``split`` when given (checked by :func:`open_root`), else the first of
    :data:`scenes.talk2radar.splits.SPLIT_PREFERENCE` (then the other lists, sorted) whose
    frames all have their files (:func:`scenes.talk2radar.splits.first_servable_split`).

    Raises:
        LaunchError: no split can be served (the first candidate's problem is named).
    """
    from scenes.talk2radar.splits import first_servable_split

    if split is not None:
        return split
    chosen, problems = first_servable_split(root)
    if chosen is None:
        raise LaunchError(f"no split can be served; {problems[0]}")
    if problems:
        log.info("serving split %r (%s)", chosen, "; ".join(problems))
    return chosen


def root_family(path: Path, talk2car: Path | None = None) -> str:
    """The dataset family of ``--data`` given with ``--talk2car``
    (:func:`scenes.datasets.source.root_family`, the one place that decides it).

    Raises:
        LaunchError: ``--talk2car`` with a root that is not a nuScenes root (one line).
    """
    from scenes.datasets.source import root_family as family
    from scenes.frame import RootError

    try:
        return family(path, talk2car)
    except RootError as exc:
        raise LaunchError(str(exc)) from exc


def open_nuscenes(
    path: Path, talk2car: Path | None, split: str | None
) -> tuple[NuScenesSource, str]:
    """A nuScenes root with its Talk2Car commands (``talk2car``: the folder of
    ``{split}_commands.json``), and the split served: ``split`` when given (``all`` or a command
    file's), else ``all`` (every sample).

    Raises:
        LaunchError: a malformed root or command file, an unknown split (one line).
    """
    from scenes.datasets.source import NuScenesSource
    from scenes.frame import RootError

    try:
        source = NuScenesSource(path, talk2car)
        return source, source.choose_split(split)
    except (RootError, OSError) as exc:  # a nuScenes table or command file error is a RootError
        raise LaunchError(str(exc)) from exc


def root_classes(path: Path) -> str:
    """The class set a served root talks about: ``nuscenes`` for a nuScenes root
    (:func:`root_family`) or a synthetic root whose manifest says so
    (:func:`scenes.synth.manifest.manifest_classes`), else ``vod``.

    Raises:
        LaunchError: an unreadable manifest (one line naming it).
    """
    from scenes.datasets.source import NUSCENES
    from scenes.synth.manifest import manifest_classes

    if root_family(path) == NUSCENES:
        return "nuscenes"
    try:
        return manifest_classes(path) or "vod"
    except ValueError as exc:
        raise LaunchError(str(exc)) from exc


def _shown(path: Path) -> str:
    """``path`` relative to the repository where it lies under it."""
    return str(path.relative_to(REPO)) if path.is_relative_to(REPO) else str(path)


def load_model(
    checkpoint: Path | None, device: str, threads: int = 1, classes: str = "vod"
) -> tuple[TPCNet, str | None]:
    """The checkpoint's model; without one the bundled checkpoint of ``classes`` (the served
    root's class set, :func:`root_classes`; ``model.checkpoint.BUNDLED``), the vod one where that
    is absent, or an untrained small one when the default checkpoint is absent too.

    ``threads`` sets torch's intra-op CPU threads for the whole process.
    """
    import torch

    from model import CheckpointError, build_model, load_checkpoint
    from model.checkpoint import BUNDLED, DEFAULT_CHECKPOINT

    if threads < 1:
        raise LaunchError(f"--threads must be >= 1, got {threads}")
    torch.set_num_threads(threads)
    if device == "cuda" and not torch.cuda.is_available():
        raise LaunchError("--device cuda: CUDA is not available on this machine")
    if checkpoint is not None:
        try:
            return load_checkpoint(checkpoint, device), None
        except (CheckpointError, OSError) as exc:
            raise LaunchError(f"--checkpoint: {exc}") from exc
    bundled = BUNDLED.get(classes, DEFAULT_CHECKPOINT)
    if bundled != DEFAULT_CHECKPOINT and bundled.is_file():
        log.info("a %s root: serving %s", classes, _shown(bundled))
        try:
            return load_checkpoint(bundled, device), None
        except CheckpointError as exc:
            raise LaunchError(f"the bundled checkpoint is unusable: {exc}") from exc
    if bundled != DEFAULT_CHECKPOINT:
        log.warning("%s not found: serving %s", _shown(bundled), _shown(DEFAULT_CHECKPOINT))
    if DEFAULT_CHECKPOINT.is_file():
        try:
            return load_checkpoint(DEFAULT_CHECKPOINT, device), None
        except CheckpointError as exc:
            raise LaunchError(f"the bundled checkpoint is unusable: {exc}") from exc
    log.warning(
        "%s not found: serving a freshly initialised small model (%s)",
        DEFAULT_CHECKPOINT.relative_to(REPO),
        UNTRAINED_NOTE,
    )
    return build_model("small").to(device).eval(), UNTRAINED_NOTE


def main(argv: Sequence[str] | None = None) -> int:
    flags = parse_args(argv)
    args = from_args(LaunchConfig, flags)
    show_warnings_as_lines()  # a notice about the root is a sentence, not a UserWarning dump
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    for noisy in ("httpx", "websockets", "urllib3"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    from app.server import AppConfig, ServerStartError, Talk2PCApp, check_listen_address
    from scenes.datasets.source import NUSCENES
    from scenes.frame import RootError

    try:
        app_flags = from_args(AppConfig, flags)
        check_listen_address(app_flags.host, app_flags.port)
        data = args.data if args.data is not None else ensure_default_data()
        if root_family(data, app_flags.talk2car) == NUSCENES:
            root, split = open_nuscenes(data, app_flags.talk2car, args.split)
        else:
            root = open_root(data, args.split)
            split = choose_split(root, args.split)
        model, note = load_model(args.checkpoint, args.device, args.threads, root_classes(data))
    except (LaunchError, ServerStartError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("Interrupted.", file=sys.stderr)
        return 130

    config = replace(
        app_flags,
        split=split,
        model_note=note,
        freeze_startup=True,  # this process only serves: cheap collections after disconnects
    )
    try:
        app = Talk2PCApp(root, model, config)
        app.start()
    except (RootError, ServerStartError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"error: cannot serve on {config.host}:{config.port}: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    # Explicit handlers: Ctrl-C works even where SIGINT was inherited as ignored (a background
    # job of a non-interactive shell), and it never interrupts the main thread mid-statement.
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    print(
        f"Talk2PC is serving {len(app.frames)} frames of {data} at {app.url} (split {split!r})",
        flush=True,
    )
    print(app.annotations.saving_line(), flush=True)
    print("Press Ctrl-C to stop.", flush=True)
    try:
        while not stop.wait(0.5):
            pass
    finally:
        print("Stopping...", flush=True)
        app.stop()
    print("Stopped.", flush=True)
    return 0


if __name__ == "__main__":
    status = main()
    # The app is stopped and the port freed by now; skip the interpreter's finalisation, which
    # takes seconds once torch and the text encoder are loaded, so that Ctrl-C feels immediate.
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)
