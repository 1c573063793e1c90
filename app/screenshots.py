"""The README's pictures, made by the repository from the shipped checkpoints:
``python -m app.screenshots [--out DIR] [--only talk2radar|nuscenes]`` (``make screenshots``).

Each picture is the app in Debian's headless Chromium (:func:`app.browser.drive`) answering a
driving command on a synthetic frame, so that the pictures are re-made whenever a checkpoint
changes:

- ``app.png``: a Talk2Radar frame (``scenes.synth``'s default sensors: 64-beam LiDAR, one 4D radar,
  camera) answered by ``checkpoints/tpcnet-small.pt``;
- ``app-nuscenes.png``: a nuScenes-like frame (``--classes nuscenes --sensors nuscenes``: the ten
  detection classes, a 32-beam LiDAR, five 2D radars, a 1600 x 900 camera) answered by
  ``checkpoints/tpcnet-nuscenes.pt``.

The frame and its command come from the data, never from what the model answers: a root is
generated with a fixed seed and every single-referent prompt phrased as a command
(``command_share=1``); the candidates are the test frames whose label_2 holds one referent, within
``--max-distance`` (25 m, so that it is large enough to see), and whose prompt reads as a command
(:func:`command_frames`), in order. The picture shows the first
candidate that the app answers correctly, one box at a 3D IoU above ``--min-iou`` (0.25) with the
labelled referent (:func:`choose_frame`); the count of candidates it passed over is printed. The
answer the browser shows is checked again before the picture is taken: a wrong answer writes no
picture and exits 2.
"""

from __future__ import annotations

import logging
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from app.browser import find_chromium
from app.view.scene_view import CameraPose, apply_pose
from scenes.utils.cli import command_parser, option, report_errors, run_command

if TYPE_CHECKING:
    import argparse

    from app.server import Talk2PCApp
    from scenes.datasets.source import Talk2RadarRoot
    from scenes.frame import Sample
    from scenes.synth.generate import SynthSettings

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / "docs" / "images"

log = logging.getLogger("talk2pc")


class ScreenshotError(ValueError):
    """No picture can be made honestly (no Chromium, no command answered correctly, a wrong
    answer in the browser). Exit status 2."""


@dataclass(frozen=True)
class Shot:
    """One picture: the synthetic root it is taken on and the checkpoint that answers.

    Attributes:
        name: The ``--only`` value.
        file: The PNG's name in ``--out``.
        classes: The class set (``scenes.synth --classes``; picks the bundled checkpoint).
        sensors: The sensor set (``scenes.synth --sensors``).
        what: The frame's kind, in words (printed).
    """

    name: str
    file: str
    classes: str
    sensors: str
    what: str


SHOTS = (
    Shot("talk2radar", "app.png", "vod", "vod", "a synthetic Talk2Radar frame"),
    Shot("nuscenes", "app-nuscenes.png", "nuscenes", "nuscenes", "a synthetic nuScenes-like frame"),
)
"""The README's pictures, in the order they are made."""


@dataclass(frozen=True, kw_only=True)
class ScreenshotConfig:
    """The flags of ``python -m app.screenshots``.

    Attributes:
        out: The folder the PNGs are written into.
        only: Make one picture (``talk2radar`` or ``nuscenes``); ``all``: both.
        frames: Frames generated per synthetic root (the candidates come from their test split).
        seed: Seed of the Talk2Radar root.
        nuscenes_seed: Seed of the nuScenes-like root.
        checkpoint: The three-class checkpoint (None: ``checkpoints/tpcnet-small.pt``).
        nuscenes_checkpoint: The ten-class checkpoint (None: ``checkpoints/tpcnet-nuscenes.pt``).
        min_iou: The 3D IoU above which the answer box is the labelled referent.
        max_distance: The farthest a candidate's referent may be (bird's-eye metres from the
            LiDAR), so that the picture shows it large enough to see.
        work: Where the synthetic roots are generated (None: a temporary folder, removed).
        timeout: Seconds each wait of the browser may take.
        threads: torch's CPU threads.
    """

    out: Path = option(DEFAULT_OUT, help="folder of the PNGs (default: docs/images)")
    only: Literal["all", "talk2radar", "nuscenes"] = option(
        "all", help="make one picture only (default %(default)s: both)"
    )
    frames: int = option(16, help="frames generated per synthetic root (default %(default)s)")
    seed: int = option(7, help="seed of the Talk2Radar root (default %(default)s)")
    nuscenes_seed: int = option(7, help="seed of the nuScenes-like root (default %(default)s)")
    checkpoint: Path | None = option(
        None, help="the three-class checkpoint (default: checkpoints/tpcnet-small.pt)"
    )
    nuscenes_checkpoint: Path | None = option(
        None, help="the ten-class checkpoint (default: checkpoints/tpcnet-nuscenes.pt)"
    )
    min_iou: float = option(
        0.25,
        help="3D IoU with the labelled referent above which an answer is correct "
        "(default %(default)s)",
    )
    max_distance: float = option(
        25.0, help="farthest referent of a candidate frame, in metres (default %(default)s)"
    )
    work: Path | None = option(
        None, help="where the synthetic roots are generated (default: a temporary folder)"
    )
    timeout: float = option(120.0, help="seconds each browser wait may take (default %(default)s)")
    threads: int = option(1, help="torch CPU threads (default %(default)s)")

    def __post_init__(self) -> None:
        if self.frames < 1:
            raise ValueError(f"--frames must be >= 1, got {self.frames}")
        if not 0.0 <= self.min_iou < 1.0:
            raise ValueError(f"--min-iou must be in [0, 1), got {self.min_iou}")
        if self.max_distance <= 0.0:
            raise ValueError(f"--max-distance must be > 0, got {self.max_distance}")
        if self.threads < 1:
            raise ValueError(f"--threads must be >= 1, got {self.threads}")

    def shots(self) -> tuple[Shot, ...]:
        """The pictures this run makes."""
        return tuple(s for s in SHOTS if self.only in ("all", s.name))

    def seed_of(self, shot: Shot) -> int:
        """The seed of ``shot``'s root."""
        return self.nuscenes_seed if shot.classes == "nuscenes" else self.seed

    def checkpoint_of(self, shot: Shot) -> Path:
        """The checkpoint that answers on ``shot``'s root (the bundled one of its class set)."""
        from model.checkpoint import BUNDLED

        given = self.nuscenes_checkpoint if shot.classes == "nuscenes" else self.checkpoint
        return given if given is not None else BUNDLED[shot.classes]


@dataclass(frozen=True)
class Choice:
    """The frame a picture shows (:func:`choose_frame`).

    Attributes:
        index: The frame's index in the test split.
        sample_id: Its sample id.
        prompt: Its own prompt (a command).
        referent: Its labelled referent ``(7,)``, LiDAR frame.
        cls: The referent's class.
        iou: The 3D IoU of the answer box with the referent.
        passed_over: Earlier candidates answered wrongly (no box, several, or the wrong one).
        candidates: Candidates in the root.
    """

    index: int
    sample_id: str
    prompt: str
    referent: np.ndarray
    cls: str
    iou: float
    passed_over: int
    candidates: int


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``python -m app.screenshots`` (:class:`ScreenshotConfig`'s flags)."""
    return command_parser(
        "python -m app.screenshots",
        "Render the README's pictures of the app (a command answered on a Talk2Radar frame and "
        "on a nuScenes-like frame) from the shipped checkpoints in headless Chromium.",
        ScreenshotConfig,
    )


def synth_settings(shot: Shot, seed: int) -> SynthSettings:
    """The generator's settings of ``shot``'s root: ``seed``, its class and sensor sets, every
    single-referent prompt phrased as a command (``scenes.synth.frame.SynthSettings``)."""
    from scenes.synth.generate import SynthSettings

    return SynthSettings(seed=seed, command_share=1.0, classes=shot.classes, sensors=shot.sensors)


def generate(shot: Shot, root: Path, frames: int, seed: int) -> Path:
    """Write ``shot``'s synthetic root (``frames`` samples, all in the test split)."""
    from scenes.synth.generate import generate_root

    generate_root(root, frames, synth_settings(shot, seed), split_fractions=(0.0, 0.0, 1.0))
    return root


def command_frames(
    root: Talk2RadarRoot, split: str = "test", max_distance: float = 25.0
) -> list[tuple[int, Sample]]:
    """``(index in the split, sample)`` of each frame whose label_2 holds exactly one referent,
    at most ``max_distance`` metres away in the bird's-eye view, and whose prompt reads as a
    driving command (``scenes.language.reading.read_prompt``), in the split's order. From the
    data alone.

    Args:
        root: The root (its class set names the classes the prompt may name).
        split: The ImageSets split.
        max_distance: The farthest referent (metres from the LiDAR, bird's-eye).
    """
    from scenes.language.reading import read_prompt

    found = []
    for index, sid in enumerate(root.ids(split)):
        sample = root.load(sid)
        if len(sample.boxes) != 1 or not sample.prompt:
            continue
        if float(np.hypot(*np.asarray(sample.boxes)[0, :2])) > max_distance:
            continue
        if read_prompt(sample.prompt, root.classes).command:
            found.append((index, sample))
    return found


def choose_frame(
    candidates: Sequence[tuple[int, Sample]],
    answer: Callable[[Sample], np.ndarray],
    min_iou: float = 0.25,
) -> Choice:
    """The first candidate whose own command ``answer`` gets right: exactly one box, at a 3D IoU
    above ``min_iou`` with the labelled referent.

    Args:
        candidates: From :func:`command_frames`.
        answer: The answer boxes ``(K, 7)`` to a sample's own prompt (the app's, at its
            threshold).
        min_iou: The IoU above which the box is the referent.

    Raises:
        ScreenshotError: no candidate, or none answered correctly.
    """
    from scenes.geometry.boxes import iou3d

    if not candidates:
        raise ScreenshotError(
            "the root has no frame whose prompt is a command about one object near enough: try "
            "another --seed, more --frames or a larger --max-distance"
        )
    for passed, (index, sample) in enumerate(candidates):
        boxes = np.asarray(answer(sample), dtype=np.float64).reshape(-1, 7)
        if len(boxes) != 1:
            continue
        referent = np.asarray(sample.boxes, dtype=np.float64).reshape(-1, 7)
        iou = float(iou3d(boxes, referent)[0, 0])
        if iou > min_iou:
            return Choice(
                index=index,
                sample_id=sample.sample_id,
                prompt=sample.prompt,
                referent=referent[0],
                cls=str(sample.classes[0]),
                iou=iou,
                passed_over=passed,
                candidates=len(candidates),
            )
    raise ScreenshotError(
        f"none of the {len(candidates)} command frames is answered with one box at 3D IoU > "
        f"{min_iou:g} with its referent: try another --seed or more --frames"
    )


def referent_pose(referent: np.ndarray, ground_z: float) -> CameraPose:
    """Behind and above the ego vehicle, looking at the referent's side of the road, so that both
    the ego vehicle's box and the referent are in sight."""
    x, y = float(referent[0]), float(referent[1])
    look = (max(8.0, 0.75 * x), 0.6 * y, ground_z)
    return CameraPose((look[0] - 24.0, 0.25 * y, ground_z + 13.0), look)


def choose_in_app(app: Talk2PCApp, root: Path, cfg: ScreenshotConfig) -> Choice:
    """:func:`choose_frame` over ``root``'s command frames with the answers ``app`` gives (its
    model, first sensor choice and initial threshold, as the browser asks; the app need not be
    started)."""
    from model import model_classes
    from scenes.datasets.source import Talk2RadarRoot

    modality = app.engine.modalities[0]
    threshold = app.score_threshold

    def answer(sample: Sample) -> np.ndarray:
        return app.engine.answer(sample, modality, sample.prompt, threshold).predictions.boxes

    served = Talk2RadarRoot(root, classes=model_classes(app.engine.model))
    frames = command_frames(served, max_distance=cfg.max_distance)
    return choose_frame(frames, answer, cfg.min_iou)


def take(shot: Shot, cfg: ScreenshotConfig, root: Path, chromium: str) -> Choice:
    """Serve ``root`` with ``shot``'s checkpoint, choose the frame (the app's own answers, at its
    threshold), answer its command in Chromium and write the picture once the answer the
    browser shows is checked.

    Raises:
        ScreenshotError: no frame answered correctly, or the browser's answer is not that one.
    """
    from app.browser import drive
    from app.server import AppConfig, Talk2PCApp
    from model.checkpoint import load_checkpoint
    from scenes.geometry.boxes import iou3d

    model = load_checkpoint(cfg.checkpoint_of(shot))
    app = Talk2PCApp(root, model, AppConfig(port=0, split="test"))
    try:
        choice = choose_in_app(app, root, cfg)
    except BaseException:
        app.stop()
        raise
    app.start()
    try:
        app.wait_ready(timeout=cfg.timeout)
        frame = app.go_to(choice.index)
        if frame is None or frame.sample.sample_id != choice.sample_id:
            raise ScreenshotError(f"the app did not show sample {choice.sample_id}")
        seen = []

        def answered() -> bool:
            for session in list(app.sessions.values()):
                got = session.answer
                if got is not None and got.prompt == choice.prompt:
                    seen.append((session, got))
            return bool(seen)

        def check_and_place() -> None:
            if not seen:
                raise ScreenshotError(f"the browser never showed an answer to {choice.prompt!r}")
            session, got = seen[0]
            boxes = np.asarray(got.predictions.boxes, dtype=np.float64).reshape(-1, 7)
            iou = float(iou3d(boxes, choice.referent[None])[0, 0]) if len(boxes) == 1 else 0.0
            if (
                got.sample_id != choice.sample_id
                or session.pred_view.count != 1
                or iou <= cfg.min_iou
            ):
                raise ScreenshotError(
                    f"the browser shows {session.pred_view.count} boxes for {choice.prompt!r} on "
                    f"{got.sample_id} (IoU {iou:.2f}): no picture written"
                )
            apply_pose(session.client.camera, referent_pose(choice.referent, frame.ground_z))

        drive(
            app.url,
            cfg.out / shot.file,
            choice.prompt,
            chromium,
            wait_answer=answered,
            before_screenshot=check_and_place,
            timeout_s=cfg.timeout,
        )
    finally:
        app.stop()
    return choice


def run(cfg: ScreenshotConfig) -> int:
    """Make the pictures of ``cfg`` (see the module docstring); 0 when all are written."""
    import torch

    chromium = find_chromium()
    if chromium is None:
        raise ScreenshotError("no Chromium found: install Debian's `chromium` package")
    torch.set_num_threads(cfg.threads)
    with tempfile.TemporaryDirectory(prefix="talk2pc-shots-") as tmp:
        work = cfg.work if cfg.work is not None else Path(tmp)
        for shot in cfg.shots():
            seed = cfg.seed_of(shot)
            root = generate(shot, work / f"{shot.name}-s{seed}", cfg.frames, seed)
            choice = take(shot, cfg, root, chromium)
            print(
                f"{cfg.out / shot.file}: {shot.what} (seed {seed}, sample {choice.sample_id}), "
                f"{cfg.checkpoint_of(shot).name} answers {choice.prompt!r} with one {choice.cls} "
                f"box at 3D IoU {choice.iou:.2f} with the labelled referent; "
                f"{choice.passed_over} of {choice.candidates} command frames passed over before "
                "it (answered wrongly)",
                flush=True,
            )
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m app.screenshots``: exit 0, or 2 with one ``error:`` line."""
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(message)s")
    # a bad flag value (ScreenshotConfig's checks) is one error line too
    return report_errors(lambda: run_command(build_parser(), ScreenshotConfig, run, argv))


if __name__ == "__main__":
    sys.exit(main())
