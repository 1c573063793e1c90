"""People's own commands: ``python -m bench.people_commands --commands FILE [--checkpoint C]``.

FILE is a Talk2Car command file (e.g. ``../shared/data/talk2car/test_commands.json``, or a
user's own download); without it the bench says so and exits 0. Each command is placed on a
synthetic frame of the checkpoint's class set where an object of the command's class is the
only one of its class ahead, on the same side and at a similar distance
(:mod:`bench.studies.people_frames`), so that the class noun alone could find it. The command is grounded
as the app grounds a typed prompt (:func:`scenes.utils.text_policy.clean_text`, then
``TPCNet.ground``) and scored against three answers on the same frames:

- **model**: the command as written;
- **class noun**: the model given only "the <noun>" of the referent's class ("the car");
- **language-blind**: the detector's most confident proposal, whatever its class.

Figures, per class and overall (percentages of the placed commands):

- **top-1**: the best-scored box is of the referent's class and its bird's-eye centre is within
  the Talk2Car top-1 distance of the referent (:func:`model.evaluation.talk2car.metrics.top1_distance`:
  1.0 m for a car, 1.5 m for a large vehicle, 0.5 m for the rest);
- **answered**: that box is also what the app shows: its score is at the checkpoint's operating
  threshold, or the sentence is a command (answered with the best box of its class whatever its
  score, :meth:`model.tpcnet.TPCNet.ground`); an empty answer is a miss;
- **model / noun**: the model's top-1 as a share of the class noun's.

The misses (command, class, side, distance, what the best box was) are written as JSON Lines to
``--misses`` (default ``data/people_commands/misses-<checkpoint>.jsonl``, outside the repository's
tracked files: the command file's licence forbids copying its sentences into the repository).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter, defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from bench.studies.people_frames import (
    CommandFileError,
    FramePlacer,
    PeopleCommand,
    PlacedFrame,
    bev_gap,
    frame_of,
    read_people_commands,
)
from scenes.synth.frame import SynthSettings
from scenes.utils.cli import command_parser, option, run_command
from scenes.utils.durable import atomic_write_text
from scenes.utils.owned import FolderError
from scenes.utils.text_policy import PROMPT, TextPolicyError, clean_text

ANSWERERS = ("model", "class noun", "language-blind")
WORLD_CACHE = Path("data/people_commands")
"""Where the searched worlds' index is kept between runs (``worlds-<classes>-<seed>.json``)."""


@dataclass
class Tally:
    """Hits of each answerer over a group of commands."""

    commands: int = 0
    top1: Counter[str] = field(default_factory=Counter)
    answered: Counter[str] = field(default_factory=Counter)

    def pct(self, answerer: str, kind: str = "top1") -> float:
        hits = (self.top1 if kind == "top1" else self.answered)[answerer]
        return 100.0 * hits / self.commands if self.commands else float("nan")

    def to_dict(self) -> dict[str, float | int]:
        out: dict[str, float | int] = {"commands": self.commands}
        for a in ANSWERERS:
            out[f"{a} top-1"] = round(self.pct(a), 2)
        for a in ANSWERERS[:2]:
            out[f"{a} answered"] = round(self.pct(a, "answered"), 2)
        return out


@dataclass(frozen=True)
class Hit:
    """One answer to one command: whether its best box is the referent, and it was answered."""

    top1: bool
    answered: bool
    best: dict[str, object]


def _is_referent(cls: str, box: np.ndarray, placed: PlacedFrame) -> bool:
    """A ``(7,)`` box of class ``cls`` is the referent: its class, and its bird's-eye centre
    within the Talk2Car top-1 distance of the referent's."""
    from model.evaluation.talk2car.metrics import top1_distance

    gap = float(bev_gap(box.reshape(1, 7), placed.referent)[0])
    return cls == placed.referent.cls and gap < top1_distance(placed.referent.cls)


def _judge(pred: object, placed: PlacedFrame, threshold: float) -> Hit:
    """Score :class:`model.core.features.Predictions` (boxes sorted by score) on a frame."""
    boxes = np.asarray(pred.boxes, dtype=np.float64).reshape(-1, 7)
    if not len(boxes):
        return Hit(False, False, {"boxes": 0})
    cls, score = pred.classes[0], float(pred.scores[0])
    top1 = _is_referent(cls, boxes[0], placed)
    gap = float(bev_gap(boxes[:1], placed.referent)[0])
    best = {"class": cls, "gap_m": round(gap, 2), "score": round(score, 3), "boxes": len(boxes)}
    best["answer_set"] = int(np.sum(np.asarray(pred.scores) >= threshold))
    reading = getattr(pred, "reading", None)
    kept = score >= threshold or (  # a command is answered with its best box (TPCNet.ground)
        reading is not None and reading.command and cls in reading.classes
    )
    return Hit(top1, top1 and kept, best)


def _blind(objects: object, placed: PlacedFrame, classes: Sequence[str]) -> bool:
    """The detector's most confident proposal (any class) is the referent."""
    if not len(objects):
        return False
    best = int(np.argmax(objects.scores))
    box = np.asarray(objects.boxes[best], dtype=np.float64)
    return _is_referent(classes[int(objects.labels[best])], box, placed)


@dataclass
class PeopleReport:
    """What a run measured."""

    checkpoint: str
    threshold: float
    by_class: dict[str, Tally]
    outside: Counter[str]
    not_placed: Counter[str]
    refused: int
    misses: list[dict[str, object]]

    def overall(self) -> Tally:
        total = Tally()
        for t in self.by_class.values():
            total.commands += t.commands
            total.top1.update(t.top1)
            total.answered.update(t.answered)
        return total

    def table(self) -> str:
        """A markdown table: per class and overall, top-1 of each answerer, answered, ratio."""
        head = (
            "| class | commands | **model top-1** | class noun | model / noun | "
            "language-blind | model answered | noun answered |"
        )
        lines = [head, "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
        rows = [*sorted(self.by_class.items()), ("**all**", self.overall())]
        for name, t in rows:
            noun = t.pct("class noun")
            ratio = 100.0 * t.top1["model"] / t.top1["class noun"] if t.top1["class noun"] else 0
            lines.append(
                f"| {name} | {t.commands} | **{t.pct('model'):.1f}** | {noun:.1f} | "
                f"{ratio:.1f} % | {t.pct('language-blind'):.1f} | "
                f"{t.pct('model', 'answered'):.1f} | {t.pct('class noun', 'answered'):.1f} |"
            )
        notes = []
        if self.outside:
            listed = ", ".join(f"{k} {v}" for k, v in self.outside.most_common())
            notes.append(f"not placed, outside the class set: {listed}")
        if self.not_placed:
            listed = ", ".join(f"{k} {v}" for k, v in self.not_placed.most_common())
            notes.append(f"not placed, no world held such an actor: {listed}")
        if self.refused:
            notes.append(f"refused by the prompt policy: {self.refused}")
        return "\n".join(lines + [f"\n{n}" for n in notes])

    def to_dict(self) -> dict[str, object]:
        return {
            "checkpoint": self.checkpoint,
            "operating_threshold": self.threshold,
            "overall": self.overall().to_dict(),
            "by_class": {k: v.to_dict() for k, v in sorted(self.by_class.items())},
            "outside_class_set": dict(self.outside),
            "not_placed": dict(self.not_placed),
            "refused": self.refused,
        }


def write_root(out: Path, placed: list[tuple[PlacedFrame, list[str]]], seed: int) -> int:
    """Write the placed frames as a Talk2Radar root: one test sample per command (its prompt
    file the command, its ``label_2`` the referent), for ``model.evaluate``. Returns the
    number of samples. ``out`` is refused unless new, empty or an earlier such root."""
    from scenes.language.prompts import Prompt
    from scenes.synth.generate import write_frame
    from scenes.talk2radar.writer import Talk2RadarWriter
    from scenes.utils.owned import owned_output

    ids: list[str] = []
    with owned_output(out, "bench.people_commands") as staging:
        writer = Talk2RadarWriter(staging, radar_folder="radar_5frames")
        for frame, texts in placed:
            referent = (frame.referent.actor_id,)
            prompts = tuple(Prompt(t, referent, frozenset({"class"})) for t in texts)
            settings = SynthSettings(seed=seed, camera=None, classes=frame.classes)
            sensed = replace(frame.frame, prompts=prompts)
            ids += write_frame(writer, sensed, len(ids), len(prompts), settings)
        writer.write_image_sets({"train": [], "val": [], "test": ids})
    return len(ids)


def run_people_commands(
    commands_file: Path,
    checkpoint: Path,
    seed: int,
    frames_per_bin: int,
    limit: int | None = None,
    progress: bool = True,
    root: Path | None = None,
    cache_dir: Path | None = None,
) -> PeopleReport:
    """Place, ground and score the commands of ``commands_file`` (module docstring); with
    ``root``, also write them as a Talk2Radar root (:func:`write_root`); with ``cache_dir``, keep
    the searched worlds' index there between runs."""
    from model import load_checkpoint, operating_threshold

    model = load_checkpoint(checkpoint)
    model.eval()
    classes = model.cfg.class_set
    threshold = operating_threshold(model)
    commands, outside = read_people_commands(commands_file, classes)
    placed_cmds = [c for c in commands if c.cls is not None]
    if limit is not None:
        placed_cmds = placed_cmds[:limit]
    by_key: dict[tuple[str, str, int], list[PeopleCommand]] = defaultdict(list)
    for c in placed_cmds:
        by_key[c.bin_key].append(c)
    cache = None if cache_dir is None else cache_dir / f"worlds-{classes.name}-{seed}.json"
    placer = FramePlacer(classes, seed, frames_per_bin, cache)
    by_class: dict[str, Tally] = {}
    not_placed: Counter[str] = Counter()
    misses: list[dict[str, object]] = []
    on_frame: dict[int, tuple[PlacedFrame, list[str]]] = {}
    refused = 0
    names = classes.names
    for key in tqdm(sorted(by_key), desc="people's commands", unit="bin", disable=not progress):
        frames = placer.frames(key)
        if not frames:
            not_placed[key[0]] += len(by_key[key])
            continue
        encoded = []
        for placed in frames:
            with torch.no_grad():
                encoded.append(
                    model.encode_scene(placed.frame.lidar.points, placed.frame.radar.points)
                )
        for command in by_key[key]:
            placed = frame_of(command, frames)
            assert placed is not None
            features = encoded[frames.index(placed)]
            try:
                text = clean_text(command.text, PROMPT)
            except TextPolicyError:
                refused += 1
                continue
            on_frame.setdefault(id(placed), (placed, []))[1].append(text)
            noun = f"the {classes.get(placed.referent.cls).noun}"
            model_hit = _judge(model.ground(features, text), placed, threshold)
            noun_hit = _judge(model.ground(features, noun), placed, threshold)
            tally = by_class.setdefault(placed.referent.cls, Tally())
            tally.commands += 1
            tally.top1["model"] += model_hit.top1
            tally.top1["class noun"] += noun_hit.top1
            tally.top1["language-blind"] += _blind(features.objects, placed, names)
            tally.answered["model"] += model_hit.answered
            tally.answered["class noun"] += noun_hit.answered
            if not model_hit.answered:
                misses.append(
                    {
                        "index": command.index,
                        "command": command.text,
                        "class": placed.referent.cls,
                        "side": command.side,
                        "distance_m": round(command.distance, 1),
                        "top1": model_hit.top1,
                        "best": model_hit.best,
                        "class_noun_top1": noun_hit.top1,
                    }
                )
    placer.save_index()
    if root is not None:
        write_root(root, list(on_frame.values()), seed)
    return PeopleReport(str(checkpoint), threshold, by_class, outside, not_placed, refused, misses)


@dataclass(frozen=True, kw_only=True)
class PeopleCommandsOptions:
    """``python -m bench.people_commands``'s flags.

    Attributes:
        commands: A Talk2Car command file (None or missing: the bench says so and exits 0).
        checkpoint: The checkpoint measured (None: the bundled ``model.DEFAULT_CHECKPOINT``).
        seed: The synthetic worlds' seed.
        frames_per_bin: Frames made per (class, side, distance bin).
        limit: Only the first N placeable commands (a quick look).
        misses: Where the misses are written (JSON Lines).
        json: Where the figures are written (JSON).
        root: Where the placed commands are written as a Talk2Radar root (None: not written).
    """

    commands: Path | None = option(None, help="a Talk2Car command file (JSON)")
    checkpoint: Path | None = option(
        None, help="a checkpoint (default: the bundled one, model.DEFAULT_CHECKPOINT)"
    )
    seed: int = option(4242, help="seed of the synthetic worlds (default %(default)s)")
    frames_per_bin: int = option(
        3, help="frames per class, side and 5 m distance bin (default %(default)s)"
    )
    limit: int | None = option(None, help="only the first N placeable commands")
    misses: Path | None = option(
        None, help="JSON Lines of the misses (default data/people_commands/misses-<ckpt>.jsonl)"
    )
    json: Path | None = option(None, help="write the figures as JSON")
    root: Path | None = option(
        None,
        help="also write the placed commands as a Talk2Radar root (one test sample per "
        "command) for python -m model.evaluate --data ROOT --split test",
    )


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.people_commands``'s parser (:class:`PeopleCommandsOptions`)."""
    return command_parser("python -m bench.people_commands", __doc__, PeopleCommandsOptions)


def _run(a: PeopleCommandsOptions) -> int:
    if a.commands is None or not a.commands.exists():
        where = "no --commands given" if a.commands is None else f"{a.commands}: no such file"
        print(f"people's commands: {where}; nothing measured (a Talk2Car command file is needed)")
        return 0
    from model import DEFAULT_CHECKPOINT

    checkpoint = DEFAULT_CHECKPOINT if a.checkpoint is None else a.checkpoint
    try:
        report = run_people_commands(
            a.commands,
            checkpoint,
            a.seed,
            a.frames_per_bin,
            a.limit,
            root=a.root,
            cache_dir=WORLD_CACHE,
        )
    except (CommandFileError, FolderError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{checkpoint} (operating threshold {report.threshold:.3f})")
    print(report.table())
    misses = a.misses or Path("data/people_commands") / f"misses-{checkpoint.stem}.jsonl"
    misses.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(misses, "".join(json.dumps(m) + "\n" for m in report.misses))
    print(f"{len(report.misses)} commands not answered with their referent: {misses}")
    if a.json is not None:
        atomic_write_text(a.json, json.dumps(report.to_dict(), indent=1) + "\n")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    return run_command(build_parser(), PeopleCommandsOptions, _run, argv)


if __name__ == "__main__":
    sys.exit(main())
