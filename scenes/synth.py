"""Generate a synthetic Talk2Radar root: ``python -m scenes.synth --out DIR --frames N --seed S``.

Each *world* (:func:`scenes.world.generate_world`) is sensed once, LiDAR
(:mod:`scenes.lidar_sim`) and accumulated radar (:mod:`scenes.radar_sim`), and yields up to
``--prompts-per-world`` prompts (:func:`scenes.prompts.generate_prompts`); every prompt becomes one
sample (Talk2Radar: one prompt per frame id) whose ``label_2`` holds the boxes of its referents and
whose sidecar ``meta/<id>.json`` keeps every actor (and, in ``extra["clutter"]``, the parked
bicycles, bicycle racks and mopeds, which are never referents and never in ``label_2``). The
samples of a world share their sensor files (hard links to ``sources/w<world>/``). ``--frames N`` is the number of samples; ids run
``00000..N-1`` in world order.

Determinism and resuming
    World ``i`` draws from ``SeedSequence([seed, i])`` (separate streams for the world, the
    weather, the LiDAR, the radar and the prompts), so it does not depend on the other worlds and
    a resumed run reproduces exactly what an uninterrupted one writes. ``synth_manifest.jsonl`` in
    the output folder records the settings (first line) and, appended after each world is fully
    written, its sample ids (one JSON line per world; a later line for the same world wins, a torn
    last line is ignored). A re-run with the same settings skips the worlds recorded there whose
    files are present and redoes any other (a world interrupted half-way is simply written again).
    A different ``--frames`` extends or shortens the set; other different settings are refused.

Splits
    By world, so that no world leaks across splits: world ``k`` (in order, counting only worlds
    that yielded samples) goes to the split furthest below its target share
    (``--split-fractions``, train / val / test), which keeps the proportions at every prefix.

Weather: ``clear`` (default), ``rain``, ``fog``, or ``mixed`` (60 / 20 / 20 % per world).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from scenes.calib import Calibration, sensor_to_lidar, vod_lidar_calibration, vod_radar_calibration
from scenes.lidar_sim import LidarConfig, LidarScan, simulate_lidar
from scenes.prompts import PHRASINGS, Prompt, PromptConfig, generate_prompts
from scenes.radar_sim import RadarConfig, RadarScan, simulate_radar
from scenes.root import SampleMeta, Talk2RadarWriter
from scenes.weather import WEATHERS, Weather
from scenes.world import RayCaster, World, WorldConfig, generate_world

MANIFEST = "synth_manifest.jsonl"
RADAR_FOLDER = {1: "radar", 3: "radar_3frames", 5: "radar_5frames"}
"""Radar tree name per number of accumulated scans (as VoD)."""
MIXED = "mixed"
MIXED_WEATHER = (("clear", 0.6), ("rain", 0.2), ("fog", 0.2))
SPLITS = ("train", "val", "test")
MAX_SAMPLES = 100_000  # 5-digit ids


class SynthError(ValueError):
    """Bad generation settings or an output folder that cannot be resumed."""


@dataclass(frozen=True)
class SynthSettings:
    """What determines the generated content (``--frames`` and the splits do not).

    Attributes:
        seed: Base seed; world ``i`` uses ``SeedSequence([seed, i])``.
        weather: ``clear``, ``rain``, ``fog`` or ``mixed``.
        radar_scans: Accumulated radar scans, 1, 3 or 5.
        prompts_per_world: Prompts (samples) drawn per world (fewer when the world has fewer).
        min_lidar_points, min_radar_points: An actor can be a referent when it has at least this
            many LiDAR points or radar points (see :func:`synthesize`).
        phrasing: Prompt wording stream, ``train``, ``heldout`` or ``all``
            (``scenes.prompts.PromptConfig.phrasing``).
    """

    seed: int = 0
    weather: str = "clear"
    radar_scans: int = 5
    prompts_per_world: int = 2
    min_lidar_points: int = 3
    min_radar_points: int = 1
    world: WorldConfig = field(default_factory=WorldConfig)
    lidar: LidarConfig = field(default_factory=LidarConfig)
    radar: RadarConfig = field(default_factory=RadarConfig)
    phrasing: str = "train"

    def __post_init__(self) -> None:
        if self.phrasing not in PHRASINGS:
            raise SynthError(f"phrasing must be one of {list(PHRASINGS)}, got {self.phrasing!r}")
        if self.seed < 0:
            raise SynthError(f"seed must be >= 0, got {self.seed}")
        if self.weather != MIXED and self.weather not in WEATHERS:
            raise SynthError(f"weather must be one of {[*WEATHERS, MIXED]}, got {self.weather!r}")
        if self.radar_scans not in RADAR_FOLDER:
            raise SynthError(f"radar_scans must be 1, 3 or 5, got {self.radar_scans}")
        if self.prompts_per_world < 1:
            raise SynthError(f"prompts_per_world must be >= 1, got {self.prompts_per_world}")

    def key(self) -> dict:
        """The settings recorded in (and compared with) the manifest."""
        return {
            "seed": self.seed,
            "weather": self.weather,
            "radar_scans": self.radar_scans,
            "prompts_per_world": self.prompts_per_world,
            # Only when not the default, so roots written before the option resume as before.
            **({"phrasing": self.phrasing} if self.phrasing != "train" else {}),
        }


@dataclass(frozen=True)
class StageTimes:
    """Seconds spent per stage on one world."""

    world: float = 0.0
    lidar: float = 0.0
    radar: float = 0.0
    prompts: float = 0.0


@dataclass(frozen=True)
class SynthFrame:
    """One sensed world and its prompts.

    Attributes:
        world: The world (actors, meshes).
        weather: Its weather.
        lidar: ``points (N, 4)`` LiDAR frame, and the owner of each point.
        radar: ``points (M, 7)`` LiDAR frame, and the owner of each point.
        prompts: Up to ``prompts_per_world`` prompts.
        sensed: Indices of the actors the prompts could refer to (seen by a sensor).
        times: Stage timings.
    """

    world: World
    weather: Weather
    lidar: LidarScan
    radar: RadarScan
    prompts: tuple[Prompt, ...]
    sensed: tuple[int, ...]
    times: StageTimes


def world_streams(seed: int, world_index: int) -> dict[str, np.random.Generator]:
    """The independent random streams of world ``world_index``."""
    children = np.random.SeedSequence([seed, world_index]).spawn(5)
    names = ("world", "weather", "lidar", "radar", "prompts")
    return {name: np.random.default_rng(s) for name, s in zip(names, children, strict=True)}


def _pick_weather(settings: SynthSettings, rng: np.random.Generator) -> Weather:
    if settings.weather != MIXED:
        return WEATHERS[settings.weather]
    names, probs = zip(*MIXED_WEATHER, strict=True)
    return WEATHERS[names[int(rng.choice(len(names), p=probs))]]


def sensed_actor_ids(
    lidar: LidarScan, radar: RadarScan, min_lidar_points: int, min_radar_points: int
) -> tuple[int, ...]:
    """Indices of the actors with at least ``min_lidar_points`` LiDAR or ``min_radar_points``
    radar points (any scan)."""
    n = int(max(lidar.owner.max(initial=-1), radar.owner.max(initial=-1))) + 1
    lidar_count = np.bincount(lidar.owner[lidar.owner >= 0], minlength=n)
    radar_count = np.bincount(radar.owner[radar.owner >= 0], minlength=n)
    seen = (lidar_count >= min_lidar_points) | (radar_count >= min_radar_points)
    return tuple(int(i) for i in np.flatnonzero(seen))


def synthesize(settings: SynthSettings, world_index: int, radar_to_lidar: np.ndarray) -> SynthFrame:
    """Build and sense world ``world_index`` and draw its prompts.

    Prompts are drawn over the *sensed* actors only (:func:`sensed_actor_ids`): an actor hidden
    from both sensors (occluded, or beyond the LiDAR's reach in fog and missed by the radar) is
    as invisible to the prompt as it would be to an annotator.

    Args:
        radar_to_lidar: ``(4, 4)`` radar -> LiDAR transform (``scenes.calib.sensor_to_lidar``).
    """
    rngs = world_streams(settings.seed, world_index)
    t0 = time.perf_counter()
    world = generate_world(rngs["world"], world_index, settings.world)
    weather = _pick_weather(settings, rngs["weather"])
    t1 = time.perf_counter()
    caster = RayCaster(world)
    lidar = simulate_lidar(caster, rngs["lidar"], settings.lidar, weather)
    t2 = time.perf_counter()
    radar = simulate_radar(
        caster, radar_to_lidar, rngs["radar"], settings.radar, weather, settings.radar_scans
    )
    t3 = time.perf_counter()
    sensed = sensed_actor_ids(lidar, radar, settings.min_lidar_points, settings.min_radar_points)
    candidates = [world.actors[i] for i in sensed]
    prompts = tuple(
        generate_prompts(
            candidates,
            rngs["prompts"],
            settings.prompts_per_world,
            config=PromptConfig(phrasing=settings.phrasing),
        )
    )
    t4 = time.perf_counter()
    times = StageTimes(world=t1 - t0, lidar=t2 - t1, radar=t3 - t2, prompts=t4 - t3)
    return SynthFrame(world, weather, lidar, radar, prompts, sensed, times)


def assign_splits(n_worlds: int, fractions: Sequence[float]) -> list[str]:
    """Split names for worlds ``0..n_worlds-1``: each goes to the split furthest below its share.

    Prefix-stable: the first ``k`` assignments do not depend on ``n_worlds``.
    """
    frac = np.asarray(fractions, dtype=np.float64)
    counts = np.zeros(len(frac))
    out = []
    for k in range(n_worlds):
        deficit = frac * (k + 1) - counts
        deficit[frac <= 0] = -np.inf
        pick = int(np.argmax(deficit))
        counts[pick] += 1
        out.append(SPLITS[pick])
    return out


def write_frame(
    writer: Talk2RadarWriter,
    frame: SynthFrame,
    first_id: int,
    count: int,
    settings: SynthSettings,
    lidar_calib: Calibration | None = None,
    radar_calib: Calibration | None = None,
) -> list[str]:
    """Write the first ``count`` prompts of ``frame`` as samples ``first_id, first_id + 1, ...``."""
    lidar_calib = lidar_calib if lidar_calib is not None else vod_lidar_calibration()
    radar_calib = radar_calib if radar_calib is not None else vod_radar_calibration()
    world = frame.world
    files = writer.write_sensors(
        f"w{world.world_id:05d}",
        frame.lidar.points,
        frame.radar.points,
        lidar_calib,
        radar_calib,
    )
    by_id = {a.actor_id: a for a in world.actors}
    seen = {world.actors[i].actor_id for i in frame.sensed}
    unseen = [a.actor_id for a in world.actors if a.actor_id not in seen]
    ids = []
    for k, prompt in enumerate(frame.prompts[:count]):
        referents = [by_id[i] for i in prompt.referent_ids]
        boxes = np.array([a.box for a in referents]).reshape(-1, 7)
        meta = SampleMeta(
            tags=prompt.tags,
            actors=world.actors,
            referent_ids=tuple(a.actor_id for a in referents),
            weather=frame.weather.name,
            ego_velocity=world.ego_speed,
            world_id=world.world_id,
            radar_scans=settings.radar_scans,
            extra={
                "generator": "scenes.synth",
                "seed": settings.seed,
                "unsensed_actor_ids": unseen,
                "clutter": [c.to_json() for c in world.clutter],
            },
        )
        ids.append(
            writer.write_sample(
                first_id + k,
                files,
                boxes,
                [a.cls for a in referents],
                prompt.text,
                meta,
                calib=lidar_calib,
            )
        )
    return ids


@dataclass(frozen=True)
class GenerationReport:
    """What :func:`generate_root` did."""

    samples: int
    worlds: int
    generated_worlds: int
    skipped_worlds: int
    seconds: float
    splits: dict[str, list[str]]


def _read_manifest(out: Path, settings: SynthSettings) -> dict[int, dict]:
    """World entries of the manifest (creating it, with the settings line, when absent)."""
    path = out / MANIFEST
    if not path.is_file():
        if (out / "lidar").exists():
            raise SynthError(
                f"{out}: holds a Talk2Radar root without {MANIFEST}; refusing to write into it"
            )
        path.write_text(json.dumps({"settings": settings.key()}) + "\n")
        return {}
    lines = path.read_text().splitlines()
    try:
        recorded = json.loads(lines[0])["settings"]
    except (IndexError, json.JSONDecodeError, KeyError, TypeError) as exc:
        raise SynthError(f"{path}:1: unreadable manifest ({exc}); delete the folder") from exc
    if recorded != settings.key():
        raise SynthError(
            f"{path}: generated with {recorded}, now asked for {settings.key()}; "
            "use another --out or delete this one"
        )
    worlds: dict[int, dict] = {}
    for lineno, line in enumerate(lines[1:], start=2):
        try:
            entry = json.loads(line)
            worlds[int(entry["world"])] = entry
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            if lineno == len(lines):  # torn by an interruption: dropped, that world is redone
                path.write_text("".join(f"{kept}\n" for kept in lines[:-1]))
                break
            raise SynthError(f"{path}:{lineno}: unreadable manifest line ({exc})") from exc
    return worlds


def _append_manifest(out: Path, entry: dict) -> None:
    with open(out / MANIFEST, "a") as handle:
        handle.write(json.dumps(entry) + "\n")
        handle.flush()
        os.fsync(handle.fileno())


def _complete_on_disk(writer: Talk2RadarWriter, ids: Sequence[str]) -> bool:
    return all(
        (tree / "training" / "label_2" / f"{sid}.txt").is_file()
        for tree in writer.trees
        for sid in ids
    )


def generate_root(
    out: str | Path,
    frames: int,
    settings: SynthSettings = SynthSettings(),
    split_fractions: Sequence[float] = (0.7, 0.1, 0.2),
    progress: bool = False,
    max_empty_worlds: int = 200,
) -> GenerationReport:
    """Write (or complete) a synthetic Talk2Radar root with ``frames`` samples; see the module doc.

    Raises:
        SynthError: bad arguments, or ``out`` holds something this run may not resume.
    """
    if not 1 <= frames <= MAX_SAMPLES:
        raise SynthError(f"frames must be in [1, {MAX_SAMPLES}], got {frames}")
    fractions = [float(f) for f in split_fractions]
    if len(fractions) != 3 or min(fractions) < 0 or abs(sum(fractions) - 1.0) > 1e-6:
        raise SynthError(
            f"split fractions must be 3 non-negative numbers summing to 1: {fractions}"
        )
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    manifest = _read_manifest(out, settings)
    writer = Talk2RadarWriter(out, radar_folder=RADAR_FOLDER[settings.radar_scans])
    lidar_calib, radar_calib = vod_lidar_calibration(), vod_radar_calibration()
    radar_to_lidar = sensor_to_lidar(lidar_calib, radar_calib)

    start = time.perf_counter()
    next_id, world_index, empty_run = 0, 0, 0
    generated = skipped = 0
    world_ids: list[list[str]] = []
    bar = tqdm(total=frames, unit="sample", desc="synth", disable=not progress)
    while next_id < frames:
        remaining = frames - next_id
        entry = manifest.get(world_index)
        if (
            entry is not None
            and entry["first_id"] == next_id
            and len(entry["ids"]) == min(entry["available"], remaining)
            and _complete_on_disk(writer, entry["ids"])
        ):
            ids = list(entry["ids"])
            skipped += 1
        else:
            frame = synthesize(settings, world_index, radar_to_lidar)
            ids = []
            if frame.prompts:
                count = min(len(frame.prompts), remaining)
                ids = write_frame(writer, frame, next_id, count, settings, lidar_calib, radar_calib)
            entry = {
                "world": world_index,
                "first_id": next_id,
                "ids": ids,
                "available": len(frame.prompts),
            }
            manifest[world_index] = entry
            _append_manifest(out, entry)
            generated += 1
        empty_run = 0 if ids else empty_run + 1
        if empty_run >= max_empty_worlds:
            raise SynthError(f"{max_empty_worlds} consecutive worlds yielded no prompt; giving up")
        if ids:
            world_ids.append(ids)
        next_id += len(ids)
        world_index += 1
        bar.update(len(ids))
    bar.close()

    splits: dict[str, list[str]] = {name: [] for name in SPLITS}
    for split, ids in zip(assign_splits(len(world_ids), fractions), world_ids, strict=True):
        splits[split].extend(ids)
    writer.write_image_sets(splits)
    return GenerationReport(
        samples=next_id,
        worlds=world_index,
        generated_worlds=generated,
        skipped_worlds=skipped,
        seconds=time.perf_counter() - start,
        splits=splits,
    )


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m scenes.synth",
        description="Generate a synthetic Talk2Radar root (LiDAR + 4D radar + grounded prompts).",
    )
    p.add_argument("--out", required=True, type=Path, help="output root folder")
    p.add_argument("--frames", required=True, type=int, help="number of samples (prompts) to write")
    p.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    p.add_argument(
        "--weather",
        default="clear",
        choices=[*WEATHERS, MIXED],
        help="weather of every world, or mixed (60/20/20 %% clear/rain/fog); default clear",
    )
    p.add_argument(
        "--radar-scans",
        type=int,
        default=5,
        choices=sorted(RADAR_FOLDER),
        help="accumulated radar scans: tree radar, radar_3frames or radar_5frames (default 5)",
    )
    p.add_argument("--prompts-per-world", type=int, default=2, help="samples per world (default 2)")
    p.add_argument(
        "--split-fractions",
        type=float,
        nargs=3,
        default=(0.7, 0.1, 0.2),
        metavar=("TRAIN", "VAL", "TEST"),
        help="share of worlds per split (default 0.7 0.1 0.2)",
    )
    p.add_argument(
        "--phrasing",
        default="train",
        choices=PHRASINGS,
        help="prompt wording: train phrasings, held-out phrasings (for measuring generalisation "
        "to other wording) or all (default train)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        settings = SynthSettings(
            seed=args.seed,
            weather=args.weather,
            radar_scans=args.radar_scans,
            prompts_per_world=args.prompts_per_world,
            phrasing=args.phrasing,
        )
        report = generate_root(
            args.out, args.frames, settings, args.split_fractions, progress=not args.quiet
        )
    except SynthError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # --out is a file, a read-only folder, a full disk...
        print(
            f"error: cannot write {exc.filename or args.out}: {exc.strerror or exc}",
            file=sys.stderr,
        )
        return 2
    counts = ", ".join(f"{k} {len(v)}" for k, v in report.splits.items())
    rate = report.samples / max(report.seconds, 1e-9)
    print(
        f"{args.out}: {report.samples} samples from {report.worlds} worlds "
        f"({report.generated_worlds} generated, {report.skipped_worlds} already complete) "
        f"in {report.seconds:.1f} s ({rate:.1f} samples/s); splits: {counts}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
