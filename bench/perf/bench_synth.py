"""Synthetic data generation speed: samples per second, and seconds per stage.

Run from the repository root::

    .venv/bin/python bench/perf/bench_synth.py            # 40 samples, default sensor settings
    .venv/bin/python bench/perf/bench_synth.py --no-camera --out /tmp/synth_nocam.json

Two measurements, both single process:

1. Stages: ``--worlds`` worlds synthesised one by one (world building, prompts, LiDAR, radar,
   camera image) and written to a temporary root (sensor files, the JPEG, one sample per
   prompt); seconds per world for each stage (mean and median).
2. End to end: ``python -m scenes.synth`` as a user runs it (:func:`scenes.synth.generate_root`,
   progress bar off) writing ``--frames`` samples into a fresh temporary folder.

Prints a Markdown table and writes ``bench/results/synth.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

_REPO = Path(__file__).resolve().parents[2]
if str(_REPO) not in sys.path:
    sys.path.insert(0, str(_REPO))

from scenes.geometry.calib import sensor_to_lidar  # noqa: E402
from scenes.synth.camera import CameraConfig  # noqa: E402
from scenes.synth.generate import (  # noqa: E402
    SynthSettings,
    generate_root,
    synthesize,
    write_frame,
)
from scenes.synth.lidar import ray_directions  # noqa: E402
from scenes.talk2radar.root import Talk2RadarWriter  # noqa: E402
from scenes.utils.cli import add_options, from_args, option  # noqa: E402
from scenes.utils.durable import atomic_write_text  # noqa: E402


def bench_stages(settings: SynthSettings, worlds: int) -> dict:
    """Per-stage seconds per world over ``worlds`` worlds (written to a temporary root)."""
    lidar_calib, radar_calib = settings.calibrations()
    radar_to_lidar = sensor_to_lidar(lidar_calib, radar_calib)
    stages: dict[str, list[float]] = {
        k: [] for k in ("world", "prompts", "lidar", "radar", "camera", "write")
    }
    samples, lidar_pts, radar_pts, actors = 0, [], [], []
    cpu0 = time.process_time()
    with tempfile.TemporaryDirectory() as tmp:
        writer = Talk2RadarWriter.for_radar_scans(tmp, settings.radar_scans)
        for index in range(worlds):
            frame = synthesize(settings, index, radar_to_lidar, lidar_calib)
            t0 = time.perf_counter()
            ids = []
            if frame.prompts:
                ids = write_frame(
                    writer, frame, samples, len(frame.prompts), settings, lidar_calib, radar_calib
                )
            stages["write"].append(time.perf_counter() - t0)
            for name in ("world", "lidar", "radar", "prompts", "camera"):
                stages[name].append(getattr(frame.times, name))
            samples += len(ids)
            lidar_pts.append(len(frame.lidar.points))
            radar_pts.append(len(frame.radar.points))
            actors.append(len(frame.world.actors))
    cpu = time.process_time() - cpu0
    per_world = {
        name: {"mean_s": statistics.fmean(v), "median_s": statistics.median(v)}
        for name, v in stages.items()
    }
    total = sum(sum(v) for v in stages.values())
    return {
        "worlds": worlds,
        "samples": samples,
        "seconds": total,
        "samples_per_second": samples / total,
        "cpu_seconds": cpu,
        "samples_per_cpu_second": samples / cpu,
        "per_world": per_world,
        "lidar_rays": len(ray_directions(settings.lidar)),
        "mean_lidar_points": float(np.mean(lidar_pts)),
        "mean_radar_points": float(np.mean(radar_pts)),
        "mean_actors": float(np.mean(actors)),
    }


def bench_end_to_end(settings: SynthSettings, frames: int) -> dict:
    """Wall time of :func:`generate_root` writing ``frames`` samples into a fresh folder."""
    with tempfile.TemporaryDirectory() as tmp:
        t0, cpu0 = time.perf_counter(), time.process_time()
        report = generate_root(Path(tmp) / "root", frames, settings)
        seconds, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    return {
        "frames": frames,
        "worlds": report.worlds,
        "seconds": seconds,
        "samples_per_second": report.samples / seconds,
        "cpu_seconds": cpu,
        "samples_per_cpu_second": report.samples / cpu,
    }


def markdown(stages: dict, e2e: dict, load: float) -> str:
    lines = [
        "| stage | mean s / world | median s / world |",
        "| --- | ---: | ---: |",
    ]
    for name, v in stages["per_world"].items():
        lines.append(f"| {name} | {v['mean_s']:.4f} | {v['median_s']:.4f} |")
    per_world = stages["seconds"] / stages["worlds"]
    lines.append(f"| **total** | **{per_world:.4f}** | |")
    lines += [
        "",
        f"- stages: {stages['samples']} samples from {stages['worlds']} worlds, "
        f"**{stages['samples_per_second']:.1f} samples/s** "
        f"({stages['samples_per_cpu_second']:.1f} per CPU second) "
        f"({stages['lidar_rays']} LiDAR rays; on average {stages['mean_lidar_points']:.0f} LiDAR "
        f"and {stages['mean_radar_points']:.0f} radar points, {stages['mean_actors']:.1f} actors "
        "per world)",
        f"- end to end (`python -m scenes.synth`): {e2e['frames']} samples from {e2e['worlds']} "
        f"worlds in {e2e['seconds']:.2f} s, **{e2e['samples_per_second']:.1f} samples/s** "
        f"({e2e['samples_per_cpu_second']:.1f} per CPU second; wall and CPU differ when other "
        "processes share the cores)",
        f"- load average before the run: {load:.2f} on {os.cpu_count()} cores",
    ]
    return "\n".join(lines)


@dataclass(frozen=True, kw_only=True)
class BenchSynthOptions:
    """``bench/perf/bench_synth.py``'s own flags (the generator's ``--seed`` is
    :class:`~scenes.synth.generate.SynthSettings`').

    Attributes:
        worlds: Worlds for the per-stage measurement.
        frames: Samples for the end-to-end run.
        no_camera: Measure without camera images.
        out: Where the JSON goes.
    """

    worlds: int = option(20, help="worlds for the per-stage measurement")
    frames: int = option(40, help="samples for the end-to-end run")
    no_camera: bool = option(False, help="measure without camera images")
    out: Path = option(_REPO / "bench" / "results" / "synth.json")


def build_parser() -> argparse.ArgumentParser:
    """``bench/perf/bench_synth.py``'s parser: :class:`BenchSynthOptions`' flags and the generator's
    ``--seed``."""
    p = argparse.ArgumentParser(
        prog="python bench/perf/bench_synth.py", description=__doc__.splitlines()[0]
    )
    add_options(p, BenchSynthOptions)
    add_options(p, SynthSettings, only=("seed",))
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parsed = build_parser().parse_args(argv)
    args = from_args(BenchSynthOptions, parsed)
    settings = from_args(SynthSettings, parsed, camera=None if args.no_camera else CameraConfig())
    load = os.getloadavg()[0]
    bench_stages(settings, 1)  # warm-up: imports, caches
    stages = bench_stages(settings, args.worlds)
    e2e = bench_end_to_end(settings, args.frames)
    table = markdown(stages, e2e, load)
    print(table)
    result = {
        "command": f"python bench/perf/bench_synth.py --worlds {args.worlds} --frames {args.frames}"
        + (" --no-camera" if args.no_camera else ""),
        "settings": settings.key(),
        "machine": {
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "python": platform.python_version(),
            "load_average_before": load,
        },
        "stages": stages,
        "end_to_end": e2e,
        "markdown": table,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, json.dumps(result, indent=1))
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
