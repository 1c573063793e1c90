"""The default output of ``python -m scenes.synth`` is pinned (``tests/synth_pins.py``).

Three tiny roots were pinned byte for byte before issue 38's sensor set-ups and sensor
randomisation were added (commit 8ef1a5a): the default VoD rig with a camera, one without a camera
(3 radar scans, mixed weather) and the ``--sensors nuscenes`` preset. Options that are not given
must change nothing: every file holds its bytes, the ray-cast scans and images their fingerprints
(embree's kernels differ by CPU; see the pins module).
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.synth_pins import differences, write_case


@pytest.mark.parametrize("case", ["camera", "no_camera", "nuscenes"])
def test_default_generation_is_the_pinned_root(case, tmp_path):
    write_case(case, tmp_path)
    changed = differences(tmp_path, case)
    assert not changed, "\n".join(changed[:8])


def test_the_pins_tell_a_changed_root_apart(tmp_path):
    """The tolerant pins are not vacuous: a label byte, a scan whose nearest 5 % of points moved
    a metre outwards, and one whose far points were dropped are each named."""
    write_case("no_camera", tmp_path)
    assert differences(tmp_path, "no_camera") == []
    velodyne = tmp_path / "lidar" / "training" / "velodyne"
    moved = _unlinked_scan(velodyne / "00000.bin")
    near = np.argsort(np.hypot(moved[:, 0], moved[:, 1]))[: len(moved) // 20]
    moved[near, :2] *= 1.0 + 1.0 / np.hypot(moved[near, 0], moved[near, 1])[:, None]
    moved.tofile(velodyne / "00000.bin")
    dropped = _unlinked_scan(velodyne / "00003.bin")
    dropped[np.hypot(dropped[:, 0], dropped[:, 1]) < 60.0].tofile(velodyne / "00003.bin")
    label = tmp_path / "lidar" / "training" / "label_2" / "00001.txt"
    label.write_text(label.read_text().replace(" ", "  ", 1))
    changed = differences(tmp_path, "no_camera")
    assert [line.split(":")[0] for line in changed] == [
        "lidar/training/label_2/00001.txt",
        "lidar/training/velodyne/00000.bin",
        "lidar/training/velodyne/00003.bin",
    ], changed


def _unlinked_scan(path):
    """A scan's points ``(N, 4)``, with ``path`` unlinked from the frames sharing its bytes."""
    points = np.fromfile(path, dtype=np.float32).reshape(-1, 4)
    path.unlink()
    return points
