"""The default output of ``python -m scenes.synth`` is pinned byte for byte.

``tests/data/synth_default_sha256.json`` holds the SHA-256 of every file of three tiny roots
written by the generator *before* issue 38's sensor set-ups and sensor randomisation were added
(commit 8ef1a5a): the default VoD rig with a camera, one without a camera (3 radar scans, mixed
weather) and the ``--sensors nuscenes`` preset. Options that are not given must change nothing.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from scenes.synth.camera import CameraConfig
from scenes.synth.generate import SynthSettings, generate_root

PINS = Path(__file__).parent / "data" / "synth_default_sha256.json"

CASES = {
    "camera": SynthSettings(seed=11, camera=CameraConfig(image_scale=0.125)),
    "no_camera": SynthSettings(seed=11, camera=None, radar_scans=3, weather="mixed"),
    "nuscenes": SynthSettings(seed=11, sensors="nuscenes", camera=CameraConfig(image_scale=0.5)),
}


def _digests(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


@pytest.mark.parametrize("case", sorted(CASES))
def test_default_generation_is_byte_identical_to_the_pinned_root(case, tmp_path):
    generate_root(tmp_path, 4, CASES[case])
    pinned = json.loads(PINS.read_text())[case]
    got = _digests(tmp_path)
    assert sorted(got) == sorted(pinned)
    changed = [name for name in pinned if got[name] != pinned[name]]
    assert not changed, f"files changed: {changed[:5]}"
