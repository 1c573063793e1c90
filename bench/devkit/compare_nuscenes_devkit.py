"""Compare :class:`scenes.nuscenes.root.NuScenesRoot` and :mod:`scenes.nuscenes.talk2car` with the
official ``nuscenes-devkit`` on a nuScenes root (an export of a synthetic root by default).

The devkit (PyPI ``nuscenes-devkit`` 1.2.0) pins ``numpy < 2`` and is not a project dependency.
Install it in a scratch virtual environment outside the repository and point this script at its
interpreter::

    python3 -m venv /tmp/devkit-venv && /tmp/devkit-venv/bin/pip install nuscenes-devkit==1.2.0
    python -m scenes.synth --out /tmp/nd-synth --frames 24 --seed 5 --camera-scale 0.25 --quiet
    python -m scenes.export_nuscenes --source /tmp/nd-synth --out /tmp/nd-nusc
    python bench/devkit/compare_nuscenes_devkit.py --root /tmp/nd-nusc --devkit-python /tmp/devkit-venv/bin/python

For every sample it compares, as the largest absolute difference over the root:

- LiDAR: the key frame's points in the LIDAR_TOP frame (``LidarPointCloud.from_file``) with
  ``NuScenesFrame.lidar`` turned back by :data:`~scenes.nuscenes.geometry.MODEL_TO_LIDAR`;
- radar multi-sweep: the five radars' ``RadarPointCloud.from_file_multisweep(..., 'LIDAR_TOP',
  nsweeps, min_distance=0)`` (default filters) with ``NuScenesFrame.radar`` (xyz in the LIDAR_TOP
  frame, rcs, ``|v_r|`` = ``hypot(vx, vy)``, ``|v_r_compensated|`` = ``hypot(vx_comp, vy_comp)``,
  the time lag = ``-radar_time``), both sorted the same way;
- boxes in the LIDAR_TOP frame (``get_sample_data(lidar)``: centre, w l h, yaw) and in the
  CAM_FRONT frame (``get_sample_data(cam, BoxVisibility.NONE)``: centre, w l h, rotation matrix)
  with ``NuScenesFrame.boxes`` (and :func:`~scenes.nuscenes.talk2car.model_box_to_camera`);
- Talk2Car: each command's camera-frame box from its ``box_token`` as ``talk2car.py`` gets it
  (``get_sample_data(cam, selected_anntokens=[box_token])``) with the referent that
  :func:`~scenes.nuscenes.talk2car.read_commands` pairs it with (through
  ``model_box_to_camera``) and with the file's own box.

The devkit is imported only in the subprocess it runs in.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

_REPO = Path(__file__).resolve().parents[2]
if str(_REPO) not in sys.path:  # run as a script: python bench/devkit/compare_nuscenes_devkit.py
    sys.path.insert(0, str(_REPO))

from scenes.nuscenes.geometry import MODEL_TO_LIDAR, quaternion_matrix, transform  # noqa: E402
from scenes.nuscenes.radar import RADAR_CHANNELS  # noqa: E402
from scenes.nuscenes.root import NuScenesRoot  # noqa: E402
from scenes.nuscenes.talk2car import commands_file, model_box_to_camera, read_commands  # noqa: E402
from scenes.utils.cli import command_parser, option, run_command  # noqa: E402

DEVKIT_SCRIPT = r"""
import json, sys
import numpy as np
from nuscenes.nuscenes import NuScenes
from nuscenes.utils.data_classes import LidarPointCloud, RadarPointCloud
from nuscenes.utils.geometry_utils import BoxVisibility
root, version, nsweeps, commands, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5]
nusc = NuScenes(version=version, dataroot=root, verbose=False)
chans = %(chans)r
res = {}
for s in nusc.sample:
    tok = s["token"]
    sd = nusc.get("sample_data", s["data"]["LIDAR_TOP"])
    res[tok + "/lidar"] = LidarPointCloud.from_file(root + "/" + sd["filename"]).points[:3].T
    pts, times = [], []
    for ch in chans:
        pc, t = RadarPointCloud.from_file_multisweep(nusc, s, ch, "LIDAR_TOP", nsweeps=nsweeps, min_distance=0.0)
        pts.append(pc.points.T); times.append(t[0])
    p, t = np.concatenate(pts), np.concatenate(times)
    res[tok + "/radar"] = np.c_[p[:, :3], p[:, 5], np.hypot(p[:, 6], p[:, 7]), np.hypot(p[:, 8], p[:, 9]), t]
    _, boxes, _ = nusc.get_sample_data(s["data"]["LIDAR_TOP"])
    res[tok + "/lidar_boxes"] = np.array([[*b.center, *b.wlh, b.orientation.yaw_pitch_roll[0]] for b in boxes]).reshape(-1, 7)
    _, boxes, _ = nusc.get_sample_data(s["data"]["CAM_FRONT"], box_vis_level=BoxVisibility.NONE)
    res[tok + "/cam_boxes"] = np.array([[*b.center, *b.wlh, *b.rotation_matrix.ravel()] for b in boxes]).reshape(-1, 15)
for split, path in json.loads(commands).items():
    for c in json.load(open(path))["commands"]:
        _, boxes, _ = nusc.get_sample_data(c["sample_token"], box_vis_level=BoxVisibility.NONE, selected_anntokens=[c["box_token"]])
        b = boxes[0]
        res["command/" + c["command_token"]] = np.array([*b.center, *b.wlh, *b.rotation_matrix.ravel()])
np.savez(out, **res)
"""


@dataclass(frozen=True)
class CompareOptions:
    """The flags of ``bench/devkit/compare_nuscenes_devkit.py``."""

    root: Path = option(help="a nuScenes root (e.g. python -m scenes.export_nuscenes's)")
    devkit_python: Path = option(help="the interpreter of a venv with nuscenes-devkit installed")
    radar_sweeps: int = option(3, help="radar sweeps accumulated (default %(default)s)")


def _match(ours: np.ndarray, devkit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two radar clouds with the devkit's rows in our order: each of our points paired with
    the nearest devkit point in (xyz, 100 x time lag); the pairing must be one to one."""
    from scipy.spatial import cKDTree

    if len(ours) != len(devkit):
        raise AssertionError(f"radar: {len(ours)} points here, {len(devkit)} in the devkit")
    if not len(ours):
        return ours, devkit
    key = np.c_[ours[:, :3], 100 * ours[:, 6]]
    _, index = cKDTree(np.c_[devkit[:, :3], 100 * devkit[:, 6]]).query(key)
    if len(set(index.tolist())) != len(index):
        raise AssertionError("radar: the nearest-point pairing is not one to one")
    return ours, devkit[index]


def _cam_rows(translation: np.ndarray, size: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    return np.r_[translation, size, quaternion_matrix(rotation).ravel()]


def compare(root_path: Path, devkit_python: Path, radar_sweeps: int) -> dict[str, float]:
    """The largest absolute difference of every compared quantity over the root's samples."""
    root = NuScenesRoot(root_path, radar_sweeps=radar_sweeps)
    folder = root_path / "commands"
    splits = [s for s in ("train", "val", "test") if commands_file(folder, s).is_file()]
    sets = {s: read_commands(folder, s, root) for s in splits}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "devkit.npz"
        script = DEVKIT_SCRIPT % {"chans": list(RADAR_CHANNELS)}
        files = json.dumps({s: str(commands_file(folder, s)) for s in splits})
        subprocess.run(
            [str(devkit_python), "-c", script, str(root_path), root.version, str(radar_sweeps), files, str(out)],
            check=True,
        )  # fmt: skip
        dk = dict(np.load(out))
    diff: dict[str, float] = {}

    def note(name: str, a: np.ndarray, b: np.ndarray) -> None:
        if a.shape != b.shape:
            raise AssertionError(f"{name}: shapes differ, ours {a.shape}, devkit {b.shape}")
        d = float(np.abs(a - b).max()) if a.size else 0.0
        diff[name] = max(diff.get(name, 0.0), d)

    counts = {"samples": 0, "lidar points": 0, "radar points": 0, "boxes": 0, "commands": 0}
    for tok in root.samples:
        f = root.frame(tok)
        counts["samples"] += 1
        lidar = transform(f.lidar[:, :3], MODEL_TO_LIDAR)
        note("lidar xyz (LIDAR_TOP frame)", lidar, dk[tok + "/lidar"])
        counts["lidar points"] += len(lidar)
        ours = np.c_[transform(f.radar[:, :3], MODEL_TO_LIDAR), f.radar[:, 3],
                     np.abs(f.radar[:, 4:6]), -f.radar_time]  # fmt: skip
        a, b = _match(ours, dk[tok + "/radar"])
        note("radar xyz (LIDAR_TOP frame)", a[:, :3], b[:, :3])
        note("radar rcs, |v_r|, |v_r_comp|", a[:, 3:6], b[:, 3:6])
        note("radar time lag (s)", a[:, 6], b[:, 6])
        counts["radar points"] += len(a)
        boxes = f.boxes
        centres = transform(boxes[:, :3], MODEL_TO_LIDAR)
        yaw = np.mod(boxes[:, 6] + np.pi / 2 + np.pi, 2 * np.pi) - np.pi
        db = dk[tok + "/lidar_boxes"]
        note("box centre (LIDAR_TOP frame)", centres, db[:, :3])
        note("box w l h", boxes[:, [4, 3, 5]], db[:, 3:6])
        note(
            "box yaw (LIDAR_TOP frame)", np.angle(np.exp(1j * (yaw - db[:, 6]))), np.zeros(len(db))
        )
        cam = np.array([_cam_rows(*model_box_to_camera(f, b)) for b in boxes]).reshape(-1, 15)
        note("box in CAM_FRONT frame (centre, wlh, rotation)", cam, dk[tok + "/cam_boxes"])
        counts["boxes"] += len(boxes)
    for cs in sets.values():
        for c in cs.commands:
            ref = cs.referent[c.command_token]
            to_camera = root.to_camera(c.sample_token)
            mine = _cam_rows(*model_box_to_camera(to_camera, ref.box))
            note(
                "Talk2Car box_token -> CAM_FRONT (read_commands)",
                mine,
                dk["command/" + c.command_token],
            )
            note(
                "Talk2Car file box vs devkit",
                _cam_rows(*c.box_camera),
                dk["command/" + c.command_token],
            )
            counts["commands"] += 1
    print(", ".join(f"{v} {k}" for k, v in counts.items()))
    return diff


def build_parser() -> argparse.ArgumentParser:
    """``bench/devkit/compare_nuscenes_devkit.py``'s parser (:class:`CompareOptions`)."""
    return command_parser(
        "python bench/devkit/compare_nuscenes_devkit.py", __doc__.split("\n\n")[0], CompareOptions
    )


def _run(opts: CompareOptions) -> int:
    """The command run as ``opts`` says."""
    diff = compare(opts.root, opts.devkit_python, opts.radar_sweeps)
    width = max(len(k) for k in diff)
    for k, v in diff.items():
        print(f"{k:<{width}}  max |ours - devkit| = {v:.2e}")
    worst = max(diff.values())
    print(f"agreement within 1e-4: {'yes' if worst <= 1e-4 else 'NO'} (largest {worst:.2e})")
    return 0 if worst <= 1e-4 else 1


def main(argv: Sequence[str] | None = None) -> int:
    return run_command(build_parser(), CompareOptions, _run, argv)


if __name__ == "__main__":
    sys.exit(main())
