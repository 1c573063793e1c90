"""Generate a synthetic Talk2Radar root: ``python -m scenes.synth --out DIR --frames N --seed S``.

Each *world* (:func:`scenes.synth.world.generate_world`) is sensed once, LiDAR
(:mod:`scenes.synth.lidar`) and accumulated radar (:mod:`scenes.synth.radar`), and yields up to
``--prompts-per-world`` prompts (:func:`scenes.language.prompts.generate_prompts`); every prompt becomes one
sample (Talk2Radar: one prompt per frame id) whose ``label_2`` holds the boxes of its referents and
whose sidecar ``meta/<id>.json`` keeps every actor (and, in ``extra["clutter"]``, the parked
bicycles, bicycle racks and mopeds, which are never referents and never in ``label_2``). The
samples of a world share their sensor files (hard links to ``sources/w<world>/``). ``--frames N`` is the number of samples; ids run
``00000..N-1`` in world order.

Camera
    Each world also gets a camera image (:mod:`scenes.synth.camera`), ``image_2/<id>.jpg`` in both trees,
    rendered at the calibration written with it: VoD's 1936 x 1216 by default (one ray per 2 x 2
    pixels, upsampled), or ``--camera-scale`` times that, with ``P2`` scaled to match and the 2D
    boxes of ``label_2`` clipped to that size. ``--no-camera`` writes no image and leaves every
    other file exactly as with the camera at scale 1.

Determinism and resuming
    World ``i`` draws from ``SeedSequence([seed, i])`` (separate streams for the world, the
    weather, the LiDAR, the radar, the prompts and the camera; :mod:`scenes.synth.frame`), so it
    does not depend on the other worlds and
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

Class sets: ``--classes vod`` (default: cars, pedestrians, cyclists; byte for byte what the
generator wrote before the option) or ``nuscenes`` (every road user of nuScenes' detection
classes, :mod:`scenes.synth.world.road_users`, and prompts about them); ``label_2`` writes each
referent's class name as :mod:`scenes.geometry.classes` spells it (``Truck``, ``TrafficCone``),
the manifest and the sidecars' ``extra`` record ``"classes"`` when it is not ``vod``.

Sensor rigs (issue 38)
    ``--sensor-setup NAME`` senses every world through a named rig of :mod:`scenes.synth.setups`
    (held-out LiDARs, mounts, intensities, radars and street densities; the same actors as the
    default rig of the seed), ``--sensor-randomise`` each world through a rig drawn by
    :mod:`scenes.synth.randomise` (each world's LiDAR calibration at its drawn height). Either
    records the rig in the sidecar's ``extra["sensor_setup"]``; without them the output is that
    of the generator before them, byte for byte (``tests/scenes/synth/test_synth_pinned.py``).

Sequences
    ``--sequence-length N`` writes ``N`` consecutive 10 Hz frames of each world
    (:func:`scenes.synth.frame.synthesize_sequence`, :func:`scenes.synth.sequence.world_at`: actors
    moved by their velocities, the ego by its speed), each with up to ``--prompts-per-world``
    samples, in frame order (ids ``first .. first + n - 1``), the frame's sensors under
    ``sources/w<world>f<k>/`` and a View-of-Delft pose file ``pose/<id>.json`` in both trees
    (:func:`scenes.synth.sequence.sequence_pose`). A sequence stops before its first frame without a
    prompt. All frames of a world go to one split. The sidecar's actors are those of the frame
    (boxes moved), and ``extra["sequence_frame"]`` is the frame's index.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.calib import Calibration, sensor_to_lidar
from scenes.synth.camera import CAMERA_SCALES, CameraConfig
from scenes.synth.frame import (
    MIXED,
    MIXED_WEATHER,
    StageTimes,
    SynthError,
    SynthFrame,
    SynthSettings,
    sensed_actor_ids,
    synthesize,
    synthesize_sequence,
    world_streams,
)
from scenes.synth.manifest import MANIFEST
from scenes.synth.sequence import sequence_pose
from scenes.talk2radar.poses import FRAME_RATE
from scenes.talk2radar.writer import Talk2RadarWriter
from scenes.utils.cli import add_options, from_args, option
from scenes.utils.durable import append_json_line, drop_torn_tail, read_json_lines

__all__ = [  # with the settings and one frame from scenes.synth.frame, re-exported
    "CAMERA_SCALES",
    "DEFAULT_SETTINGS",
    "DEFAULT_SPLIT_FRACTIONS",
    "MANIFEST",
    "MAX_SAMPLES",
    "MIXED",
    "MIXED_WEATHER",
    "SPLITS",
    "GenerationReport",
    "StageTimes",
    "SynthCommand",
    "SynthError",
    "SynthFrame",
    "SynthSettings",
    "assign_splits",
    "generate_root",
    "main",
    "sensed_actor_ids",
    "synthesize",
    "synthesize_sequence",
    "world_streams",
    "write_frame",
]

SPLITS = ("train", "val", "test")
MAX_SAMPLES = 100_000  # 5-digit ids
DEFAULT_SETTINGS = SynthSettings()
"""The settings of ``python -m scenes.synth`` without options."""
DEFAULT_SPLIT_FRACTIONS = (0.7, 0.1, 0.2)
"""Share of worlds per split, train / val / test (``--split-fractions``' default)."""


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
    sequence_frame: int | None = None,
) -> list[str]:
    """Write the first ``count`` prompts of ``frame`` as samples ``first_id, first_id + 1, ...``
    (calibrations default to ``settings.calibrations()``, which match the camera image).

    ``sequence_frame``: the frame's index in its world's sequence (``--sequence-length``): its
    sensors go to ``sources/w<world>f<k>/`` (``w<world>`` for frame 0, as without sequences),
    every sample gets the frame's pose file (:func:`scenes.synth.sequence.sequence_pose`) and its
    sidecar records ``extra["sequence_frame"]``. None: no sequence (no pose file).
    """
    default_lidar, default_radar = settings.calibrations()
    lidar_calib = lidar_calib if lidar_calib is not None else default_lidar
    radar_calib = radar_calib if radar_calib is not None else default_radar
    world = frame.world
    key = f"w{world.world_id:05d}"
    if sequence_frame:
        key += f"f{sequence_frame:03d}"
    files = writer.write_sensors(
        key,
        frame.lidar.points,
        frame.radar.points,
        lidar_calib,
        radar_calib,
        image=frame.image,
        jpeg_quality=settings.camera.jpeg_quality if settings.camera is not None else 90,
    )
    by_id = {a.actor_id: a for a in world.actors}
    seen = {world.actors[i].actor_id for i in frame.sensed}
    unseen = [a.actor_id for a in world.actors if a.actor_id not in seen]
    preset = settings.sensor_set()
    setup = frame.setup
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
            radar_scans=settings.radar_scans if setup is None else setup.radar_scans,
            extra={
                "generator": "scenes.synth",
                "seed": settings.seed,
                "unsensed_actor_ids": unseen,
                "clutter": [c.to_json() for c in world.clutter],
                **({"sensors": preset.meta()} if preset is not None else {}),
                **({"classes": settings.classes} if settings.classes != "vod" else {}),
                **({"sensor_setup": setup.meta()} if setup is not None else {}),
                **({"sequence_frame": sequence_frame} if sequence_frame is not None else {}),
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
    if sequence_frame is not None:
        ego_x = frame.world.ego_speed * sequence_frame / FRAME_RATE
        pose = sequence_pose(frame.world.world_id, ego_x, lidar_calib)
        for sid in ids:
            writer.write_pose(sid, pose)
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


def _manifest_line(value: object) -> dict:
    """A manifest line: the settings (line 1) or a world entry; KeyError / TypeError / ValueError
    for anything else."""
    if not isinstance(value, dict) or not ("settings" in value or "world" in value):
        raise ValueError("neither the settings nor a world entry")
    if "settings" not in value:
        int(value["world"])
    return value


def _read_manifest(out: Path, settings: SynthSettings) -> dict[int, dict]:
    """World entries of the manifest (creating it, with the settings line, when absent). A torn
    last line (an interrupted append) is cut off: that world is redone."""
    path = out / MANIFEST
    if not path.is_file():
        if Talk2RadarWriter.holds_root(out):
            raise SynthError(
                f"{out}: holds a Talk2Radar root without {MANIFEST}; refusing to write into it"
            )
        append_json_line(path, {"settings": settings.key()})
        return {}
    log = read_json_lines(path, _manifest_line)
    first = log.entries[0] if log.entries else None
    if first is None or first[0] != 1 or "settings" not in first[1]:
        why = log.unreadable[0][1] if log.unreadable else "no settings line"
        raise SynthError(f"{path}:1: unreadable manifest ({why}); delete the folder")
    recorded = first[1]["settings"]
    if recorded != settings.key():
        raise SynthError(
            f"{path}: generated with {recorded}, now asked for {settings.key()}; "
            "use another --out or delete this one"
        )
    for lineno, why in log.unreadable:
        if lineno != log.last_line:  # only the last line can be torn by an interruption
            raise SynthError(f"{path}:{lineno}: unreadable manifest line ({why})")
    drop_torn_tail(log)
    worlds: dict[int, dict] = {}
    for lineno, entry in log.entries[1:]:
        if "world" not in entry:
            raise SynthError(f"{path}:{lineno}: unreadable manifest line (a second settings line)")
        worlds[int(entry["world"])] = entry
    return worlds


def _prompted_frames(frames: Sequence[SynthFrame]) -> list[SynthFrame]:
    """The frames of a sequence up to the first one without a prompt (a sample needs a
    prompt, and a sequence with a frame missing would not be one of consecutive frames)."""
    out = []
    for frame in frames:
        if not frame.prompts:
            break
        out.append(frame)
    return out


def generate_root(
    out: str | Path,
    frames: int,
    settings: SynthSettings = DEFAULT_SETTINGS,
    split_fractions: Sequence[float] = DEFAULT_SPLIT_FRACTIONS,
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
    writer = Talk2RadarWriter.for_radar_scans(out, settings.radar_scans)
    lidar_calib, radar_calib = settings.calibrations()
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
            and writer.has_samples(entry["ids"])
        ):
            ids = list(entry["ids"])
            skipped += 1
        else:
            if settings.sensor_randomise:  # each world's LiDAR at its own height
                lidar_calib, radar_calib = settings.calibrations(settings.world_setup(world_index))
                radar_to_lidar = sensor_to_lidar(lidar_calib, radar_calib)
            drive = _prompted_frames(
                synthesize_sequence(
                    settings, world_index, radar_to_lidar, lidar_calib, settings.sequence_length
                )
            )
            ids = []
            sequence = settings.sequence_length > 1
            for k, frame in enumerate(drive):
                count = min(len(frame.prompts), remaining - len(ids))
                if count <= 0:
                    break
                ids += write_frame(
                    writer,
                    frame,
                    next_id + len(ids),
                    count,
                    settings,
                    lidar_calib,
                    radar_calib,
                    sequence_frame=k if sequence else None,
                )
            entry = {
                "world": world_index,
                "first_id": next_id,
                "ids": ids,
                "available": sum(len(f.prompts) for f in drive),
            }
            manifest[world_index] = entry
            append_json_line(out / MANIFEST, entry)
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


@dataclass(frozen=True, kw_only=True)
class SynthCommand:
    """The flags of ``python -m scenes.synth`` that are not generation settings (those are
    :class:`SynthSettings`' and the camera's :class:`scenes.synth.camera.CameraConfig`'s fields).

    Attributes:
        out: Output root folder.
        frames: Number of samples (prompts) to write.
        split_fractions: Share of worlds per split, train / val / test.
        no_camera: Write no camera images (``SynthSettings.camera`` None).
        quiet: No progress bar.
    """

    out: Path = option(help="output root folder")
    frames: int = option(help="number of samples (prompts) to write")
    split_fractions: tuple[float, float, float] = option(
        (0.7, 0.1, 0.2),
        metavar=("TRAIN", "VAL", "TEST"),
        help="share of worlds per split (default %(default)s)",
    )
    no_camera: bool = option(False, help="write no camera images (image_2)")
    quiet: bool = option(False, help="no progress bar")


_FLAG_ORDER: tuple[tuple[type, tuple[str, ...]], ...] = (
    (SynthCommand, ("out", "frames")),
    (SynthSettings, ("seed", "weather", "sensors", "radar_scans", "prompts_per_world")),
    (SynthSettings, ("sensor_setup", "sensor_randomise")),
    (SynthCommand, ("split_fractions",)),
    (SynthSettings, ("phrasing", "language", "command_share", "people_share", "classes")),
    (SynthCommand, ("no_camera",)),
    (CameraConfig, ("image_scale", "ray_step")),
    (SynthSettings, ("sequence_length",)),
    (SynthCommand, ("quiet",)),
)
"""Which dataclass each flag comes from, in ``--help``'s order."""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m scenes.synth",
        description="Generate a synthetic Talk2Radar root (LiDAR + 4D radar + grounded prompts).",
    )
    for cls, names in _FLAG_ORDER:
        add_options(p, cls, only=names)
    return p


def _camera_config(args: argparse.Namespace) -> CameraConfig | None:
    """The camera of the command line (None with ``--no-camera``); SynthError when bad."""
    if args.no_camera:
        return None
    try:
        return from_args(CameraConfig, args)
    except ValueError as exc:
        raise SynthError(f"camera: {exc}") from exc


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    command = from_args(SynthCommand, args)
    try:
        settings = from_args(SynthSettings, args, camera=_camera_config(args))
        report = generate_root(
            command.out,
            command.frames,
            settings,
            command.split_fractions,
            progress=not command.quiet,
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
