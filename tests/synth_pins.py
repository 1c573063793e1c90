"""Pins of the generator's default output that hold on every x86 CPU.

``tests/data/synth_pins.json`` holds, for each tiny root of :data:`CASES`, every file the root has:
the SHA-256 of the file's bytes, except for the files made by ray casting (LiDAR scans and camera
images), which are pinned by a :func:`fingerprint` compared within float tolerance.

Why: embree picks its kernels by the CPU's instruction set at run time, and a ray that grazes a
triangle's edge can hit with one set of kernels and miss with another. The three roots of
``camera`` / ``no_camera`` / ``nuscenes`` were pinned byte for byte at 8ef1a5a on the machine
where CI used to run; on an AVX2 machine without AVX-512 (this project's CI since stop 52) every
label, prompt, radar scan, calibration and meta file stays byte for byte the same, and so do 3 of
the 4 frames' LiDAR scans and images; world 0's do not, because a few of its rays land otherwise.
A byte pin of those files tests the CPU, not the code.

A fingerprint still fails on any change of the code that moves points or pixels: the number of
points (a few), histograms of where they are (azimuth x range, height, intensity) within 0.2 % of
the points, each channel's mean within 0.01 (m, or grey levels), an image's 8 x 8 block means
within 1 grey level. The exact files catch everything upstream of the ray caster (worlds,
sampling, labels, prompts, the random streams).

The pins were written by ``python -m tests.synth_pins`` on 03fdd52, whose output on the AVX2
machine is byte-identical to db736f4's (checked), which matched the earlier byte pins where CI
passed. Write them again only for an intended change of the generator's output, and say why.
"""

from __future__ import annotations

import argparse
import fnmatch
import hashlib
import json
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

from scenes.synth.camera import CameraConfig
from scenes.synth.generate import SynthSettings, generate_root
from scenes.synth.generate import main as synth_main
from tests.paths import TEST_DATA

PINS = TEST_DATA / "synth_pins.json"

RAY_CAST = (
    "lidar/*/velodyne/*.bin",
    "sources/*/lidar.bin",
    "*/image_2/*.jpg",
    "sources/*/image.jpg",
)
"""Root-relative patterns of the files made by ray casting (pinned by fingerprint)."""

TINY_ROOT = [
    "--frames", "3", "--seed", "7", "--prompts-per-world", "2", "--quiet",
    "--camera-scale", "0.125", "--camera-ray-step", "1",
]  # fmt: skip
"""``python -m scenes.synth --out R *TINY_ROOT``: the ``tiny`` case, written through the CLI."""

CASES: dict[str, tuple[int, SynthSettings]] = {
    "camera": (4, SynthSettings(seed=11, camera=CameraConfig(image_scale=0.125))),
    "no_camera": (4, SynthSettings(seed=11, camera=None, radar_scans=3, weather="mixed")),
    "nuscenes": (
        4,
        SynthSettings(seed=11, sensors="nuscenes", camera=CameraConfig(image_scale=0.5)),
    ),
    "base": (4, SynthSettings(seed=5, camera=None)),
    "extended": (
        6,
        SynthSettings(
            seed=7,
            camera=None,
            prompts_per_world=3,
            language="extended",
            command_share=0.3,
            phrasing="heldout",
        ),
    ),
}
"""Pinned roots written by :func:`generate_root` (count, settings); ``tiny`` is the CLI's."""

AZIMUTH_BINS = 24
RANGE_EDGES = (5.0, 10.0, 20.0, 40.0, 80.0)
HEIGHT_EDGES = (-1.0, 0.0, 1.0, 2.0)
INTENSITY_BINS = 8
POINT_SLACK = 2
"""Points that may differ (count, each histogram's L1 distance) beyond the relative share."""
POINT_SHARE = 0.002
MEAN_SHIFT = 0.01
"""Largest move of a channel's mean (m for x, y, z; grey levels for intensity)."""
BLOCKS = 8
GREY_LEVELS = 1.0


def write_case(name: str, out: Path) -> None:
    """Write the pinned root ``name`` (a key of :data:`CASES` or ``tiny``) to ``out``."""
    if name == "tiny":
        if synth_main(["--out", str(out), *TINY_ROOT]) != 0:
            raise RuntimeError("scenes.synth failed on the tiny root")
        return
    count, settings = CASES[name]
    generate_root(out, count, settings)


def _is_ray_cast(name: str) -> bool:
    return any(fnmatch.fnmatch(name, pattern) for pattern in RAY_CAST)


def _point_fingerprint(points: np.ndarray) -> dict:
    """``points (N, 4)`` float32 (x, y, z, intensity; LiDAR frame): counts by azimuth x range,
    height and intensity."""
    xyz = points[:, :3].astype(np.float64)
    azimuth = np.floor((np.arctan2(xyz[:, 1], xyz[:, 0]) + np.pi) / (2 * np.pi) * AZIMUTH_BINS)
    azimuth = np.clip(azimuth.astype(int), 0, AZIMUTH_BINS - 1)
    rng = np.digitize(np.hypot(xyz[:, 0], xyz[:, 1]), RANGE_EDGES)
    polar = np.bincount(azimuth * (len(RANGE_EDGES) + 1) + rng)
    polar = np.pad(polar, (0, AZIMUTH_BINS * (len(RANGE_EDGES) + 1) - len(polar)))
    height = np.bincount(np.digitize(xyz[:, 2], HEIGHT_EDGES), minlength=len(HEIGHT_EDGES) + 1)
    intensity = np.histogram(points[:, 3], bins=INTENSITY_BINS, range=(0.0, 256.0))[0]
    return {
        "points": int(len(points)),
        "means": points.astype(np.float64).mean(axis=0).round(5).tolist(),
        "polar": polar.tolist(),
        "height": height.tolist(),
        "intensity": intensity.tolist(),
    }


def _image_fingerprint(path: Path) -> dict:
    """An image's shape and its ``BLOCKS x BLOCKS`` grid of per-channel mean grey levels."""
    pixels = np.asarray(Image.open(path).convert("RGB"), dtype=np.float64)
    h, w, _ = pixels.shape
    rows = np.array_split(np.arange(h), BLOCKS)
    cols = np.array_split(np.arange(w), BLOCKS)
    means = [[pixels[r][:, c].mean(axis=(0, 1)).round(3).tolist() for c in cols] for r in rows]
    return {"shape": [h, w], "blocks": means}


def fingerprint(path: Path) -> dict:
    """The tolerant pin of a ray-cast file (a ``.bin`` scan or a ``.jpg`` image)."""
    if path.suffix == ".bin":
        return _point_fingerprint(np.fromfile(path, dtype=np.float32).reshape(-1, 4))
    return _image_fingerprint(path)


def root_pins(root: Path) -> dict[str, str | dict]:
    """Every file of ``root`` by relative path: its SHA-256, or its :func:`fingerprint`."""
    pins: dict[str, str | dict] = {}
    for path in sorted(p for p in root.rglob("*") if p.is_file()):
        name = path.relative_to(root).as_posix()
        pins[name] = fingerprint(path) if _is_ray_cast(name) else _sha256(path)
    return pins


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _fingerprint_difference(got: dict, want: dict) -> str | None:
    """Why two fingerprints differ beyond the tolerance, or ``None``."""
    if "points" in want:
        slack = POINT_SLACK + POINT_SHARE * want["points"]
        if abs(got["points"] - want["points"]) > slack:
            return f"{got['points']} points, pinned {want['points']}"
        shift = float(np.abs(np.subtract(got["means"], want["means"])).max())
        if shift > MEAN_SHIFT:
            return f"a channel's mean moved by {shift:.4f} (tolerance {MEAN_SHIFT})"
        for key in ("polar", "height", "intensity"):
            moved = int(np.abs(np.subtract(got[key], want[key])).sum())
            if moved > slack:
                return f"{moved} points moved between {key} bins (tolerance {slack:.0f})"
        return None
    if got["shape"] != want["shape"]:
        return f"image {got['shape']}, pinned {want['shape']}"
    worst = float(np.abs(np.subtract(got["blocks"], want["blocks"])).max())
    if worst > GREY_LEVELS:
        return f"a block's mean moved {worst:.2f} grey levels (tolerance {GREY_LEVELS})"
    return None


def differences(root: Path, case: str) -> list[str]:
    """How ``root`` differs from the pinned root ``case``: one line per file (empty: it holds)."""
    want = json.loads(PINS.read_text())[case]
    got = root_pins(root)
    lines = [f"{name}: missing" for name in sorted(set(want) - set(got))]
    lines += [f"{name}: not pinned" for name in sorted(set(got) - set(want))]
    for name in sorted(set(got) & set(want)):
        if isinstance(want[name], str):
            if got[name] != want[name]:
                lines.append(f"{name}: bytes changed")
        else:
            why = _fingerprint_difference(got[name], want[name])
            if why:
                lines.append(f"{name}: {why}")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="write tests/data/synth_pins.json")
    parser.add_argument("--out", type=Path, default=PINS, help="pins file to write")
    args = parser.parse_args(argv)
    pins = {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in [*CASES, "tiny"]:
            write_case(case, Path(tmp) / case)
            pins[case] = root_pins(Path(tmp) / case)
    args.out.write_text(json.dumps(pins, indent=1, sort_keys=True) + "\n")
    print(f"{args.out}: {sum(len(v) for v in pins.values())} files in {len(pins)} roots")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
