"""Messages a person reads are sentences (issue 51.5).

- ``python launch.py`` serving a View-of-Delft release without an ImageSets folder says so in one
  ``warning:`` sentence, not Python's raw ``...py:243: UserWarning: ...`` display with its source
  line.
- ``python -m scenes.export_nuscenes`` ends with sentences: how many prompts were left out and
  why, each count with its reason ("14 with 2 referents"), never a bare list of numbers and
  labels ("prompts left out: 14 2 referents, not one, 2 4 referents, not one").
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

from scenes.synth.generate import SynthSettings, generate_root
from tests.paths import REPO


def test_serving_a_release_without_image_sets_says_so_in_a_sentence(
    tmp_path, write_vod_root
) -> None:
    root = write_vod_root(tmp_path / "example", frames=3, splits={})
    assert not (root / "lidar" / "ImageSets").exists()
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
    proc = subprocess.Popen(
        [sys.executable, "launch.py", "--data", str(root), "--port", "0", "--threads", "1"],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 240
        out = []
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            out.append(line)
            if "Press Ctrl-C to stop." in line:
                break
        assert any("Press Ctrl-C" in line for line in out), "".join(out)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    notices = [line for line in err.splitlines() if "ImageSets" in line]
    assert len(notices) == 1, err
    (notice,) = notices
    assert re.fullmatch(
        r"warning: \S+/lidar has no ImageSets folder, so all 3 frames of \S+/velodyne are "
        r"served as split 'all' \(and as any other split\)\.",
        notice,
    ), notice
    assert "UserWarning" not in err and "warnings.warn" not in err


def test_the_nuscenes_exporter_says_which_prompts_it_left_out_in_a_sentence(
    tmp_path, capsys
) -> None:
    from scenes.export_nuscenes import main

    source = tmp_path / "synth"
    generate_root(source, 8, SynthSettings(seed=4, prompts_per_world=4, camera=None))
    assert main(["--source", str(source), "--out", str(tmp_path / "nusc")]) == 0
    (line,) = capsys.readouterr().out.strip().splitlines()
    assert "referents, not one" not in line
    found = re.search(
        r"\. (\d+) prompts? (?:was|were) left out \(a Talk2Car command refers to exactly one "
        r"object, in front of CAM_FRONT\): (.+)\.$",
        line,
    )
    assert found, line
    reasons = re.split(r", | and (?=\d)", found.group(2))
    counts = []
    for reason in reasons:
        part = re.fullmatch(
            r"(\d+) (with \d+ referents|with no referent|whose referent is not wholly in front "
            r"of CAM_FRONT)",
            reason,
        )
        assert part, reason
        counts.append(int(part.group(1)))
    assert sum(counts) == int(found.group(1)) > 0
    assert re.search(r"commands: \d+ in \w+", line), line
