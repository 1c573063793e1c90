"""Serve the Talk2PC app: ``python launch.py [--data ROOT] [--checkpoint PATH] [--host 127.0.0.1]
[--port 8080] [--device cpu|cuda] [--split test] [--threads 1]``.

- No ``--data``: a small deterministic synthetic set is generated once into ``data/default``
  (``python -m scenes.synth --out data/default --frames 60 --seed 0``, about 10 s) and served;
  later runs reuse it. A generation interrupted half-way resumes where it stopped.
- No ``--checkpoint``: the bundled ``checkpoints/tpcnet-small.pt``. Where it does not exist yet, a
  freshly initialised small model is served with a warning in the log and in every browser panel
  ("untrained model: boxes are meaningless").
- A ``--checkpoint`` or ``--data`` that is missing or invalid, an unknown split, a split where no
  frame loads, ``--device cuda`` without CUDA, a ``--port`` outside 0..65535, a ``--host`` that is
  not an address of this machine, or a server that does not listen within 20 s: a one-line error
  on stderr and exit code 2, within seconds (the host and port are checked before anything else).

The URL is printed once the server listens; Ctrl-C (or SIGTERM) stops it cleanly (exit code 0).
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
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from model.tpcnet import TPCNet
    from scenes.root import Talk2RadarRoot

REPO = Path(__file__).resolve().parent
DEFAULT_DATA = REPO / "data" / "default"
DEFAULT_CHECKPOINT = REPO / "checkpoints" / "tpcnet-small.pt"
DEFAULT_FRAMES = 60
DEFAULT_SEED = 0
COMPLETE_MARKER = ".talk2pc-complete"
"""Written into ``data/default`` once the synthetic set is fully generated."""

UNTRAINED_NOTE = "untrained model: boxes are meaningless"

log = logging.getLogger("talk2pc")


class LaunchError(Exception):
    """A user error: bad flags, a missing or invalid file. Exit code 2."""


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python launch.py",
        description="Serve the Talk2PC viser app: type a sentence, see the referred objects boxed.",
    )
    p.add_argument(
        "--data",
        type=Path,
        default=None,
        help=f"a Talk2Radar root (default: synthetic scenes generated into {DEFAULT_DATA})",
    )
    p.add_argument(
        "--checkpoint",
        type=Path,
        default=None,
        help=f"a TPCNet checkpoint (default: {DEFAULT_CHECKPOINT.relative_to(REPO)})",
    )
    p.add_argument("--host", default="127.0.0.1", help="interface to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8080, help="port (default 8080; 0 = any free)")
    p.add_argument("--device", default="cpu", choices=("cpu", "cuda"), help="model device")
    p.add_argument("--split", default="test", help="ImageSets split to browse (default test)")
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        help="CPU threads per model call (default 1: on a small shared machine, torch's "
        "multi-threaded kernels slow down badly once the cores are busy)",
    )
    return p.parse_args(argv)


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
    (out / COMPLETE_MARKER).write_text(f"frames={frames} seed={seed}\n")
    return out


def open_root(path: Path, split: str) -> Talk2RadarRoot:
    """Open a root and check the split; :class:`LaunchError` otherwise."""
    from scenes.root import RootError, Talk2RadarRoot

    if not path.is_dir():
        raise LaunchError(f"--data {path}: no such folder")
    try:
        root = Talk2RadarRoot(path)
        ids = root.ids(split)
    except RootError as exc:
        raise LaunchError(str(exc)) from exc
    if not ids:
        raise LaunchError(f"{path}: split {split!r} lists no frame (splits: {root.splits()})")
    return root


def load_model(checkpoint: Path | None, device: str, threads: int = 1) -> tuple[TPCNet, str | None]:
    """The checkpoint's model, or an untrained small one when the default checkpoint is absent.

    ``threads`` sets torch's intra-op CPU threads for the whole process.
    """
    import torch

    from model import build_model
    from model.checkpoint import CheckpointError, load_checkpoint

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
    args = parse_args(argv)
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    for noisy in ("httpx", "websockets", "urllib3"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    from app.server import AppConfig, ServerStartError, Talk2PCApp, check_listen_address
    from scenes.root import RootError

    try:
        check_listen_address(args.host, args.port)
        data = args.data if args.data is not None else ensure_default_data()
        root = open_root(data, args.split)
        model, note = load_model(args.checkpoint, args.device, args.threads)
    except (LaunchError, ServerStartError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("Interrupted.", file=sys.stderr)
        return 130

    config = AppConfig(host=args.host, port=args.port, split=args.split, model_note=note)
    try:
        app = Talk2PCApp(root, model, config)
        app.start()
    except (RootError, ServerStartError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"error: cannot serve on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    # Explicit handlers: Ctrl-C works even where SIGINT was inherited as ignored (a background
    # job of a non-interactive shell), and it never interrupts the main thread mid-statement.
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    print(f"Talk2PC is serving {len(app.frames)} frames of {data} at {app.url}", flush=True)
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
