"""Issue 50 item 5, second half: a frozen torchrun rank ends the run within a bound set from the
step's own duration, with one line naming the rank.

Round 4's rank watch (model/training/rank_watch.py) waited a fixed minute for a stopped rank, so a
run of sub-second steps sat silent for as long; now its limit is a multiple of the median recent
step, at least :data:`FLOOR_S`, at most ``TALK2PC_RANK_TIMEOUT``.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

import pytest

from model.training.rank_watch import (
    FLOOR_S,
    STARTUP_LIMIT_S,
    STEP_MULTIPLE,
    RankLiveness,
    RankWatch,
)
from tests.paths import REPO

pytestmark = pytest.mark.serial  # the run must end within its step bound


def test_the_limit_follows_the_steps_within_floor_and_cap() -> None:
    live = RankLiveness()
    assert live.limit(None) == STARTUP_LIMIT_S  # nothing timed yet
    assert live.limit(0.05) == FLOOR_S  # fast steps: the floor
    assert live.limit(1.0) == pytest.approx(STEP_MULTIPLE * 1.0)
    assert live.limit(30.0) == live.limit_s  # slow steps: the cap (TALK2PC_RANK_TIMEOUT)
    assert live.beat_s <= FLOOR_S / 5
    capped = RankLiveness(3.0)  # the variable below the floor caps every limit
    assert capped.limit(None) == capped.limit(0.01) == capped.limit(100.0) == 3.0


def test_the_watch_uses_its_median_recent_step_after_the_first() -> None:
    class Store:
        def __init__(self) -> None:
            self.data: dict[str, bytes] = {}

        def set(self, key: str, value: str) -> None:
            self.data[key] = value.encode()

        def get(self, key: str) -> bytes:
            return self.data[key]

        def check(self, keys: list[str]) -> bool:
            return all(k in self.data for k in keys)

    live = RankLiveness(60.0, startup_s=30.0, floor_s=0.2, step_multiple=4.0)
    store = Store()
    zero, one = RankWatch(store, 0, 2, live), RankWatch(store, 1, 2, live)
    assert zero.limit() == 30.0
    zero.note_step(5.0)  # the first step: its warm-up, left out
    assert zero.limit() == 30.0
    for seconds in (0.1, 0.3, 0.05):
        zero.note_step(seconds)
    assert zero.limit() == pytest.approx(0.4)  # 4 x the median (0.1 s)
    one._beat()
    assert zero.stopped_rank() is None
    time.sleep(0.5)  # rank 1 frozen: no beat for longer than 0.4 s
    found = zero.stopped_rank()
    assert found is not None and found[0] == 1


def test_a_frozen_rank_ends_the_run_within_the_step_bound(
    tmp_path: Path, torchrun, monkeypatch
) -> None:
    """Steps of about 0.05 s, then rank 1 stopped by SIGSTOP, TALK2PC_RANK_TIMEOUT unset: rank
    0 names rank 1 within the floor (10 s) plus a beat, where the fixed limit waited a minute
    (and gloo's own timeout 30)."""
    monkeypatch.delenv("TALK2PC_RANK_TIMEOUT", raising=False)
    log = tmp_path / "torchrun.log"
    code = torchrun(
        [str(Path(__file__).with_name("rank_freeze_check.py")), "20", "0.05"], log, timeout=120
    )
    ended = time.time()
    text = log.read_text()
    lines = [line for line in text.splitlines() if line.startswith("error: rank")]
    assert code != 0 and len(lines) == 1, text[-3000:]
    line = lines[0]
    assert line.startswith("error: rank 1 (pid ") and "it was killed" in line, line
    assert f"{STEP_MULTIPLE:g} x the median recent step" in line and "--resume" in line, line
    limit = float(re.search(r"has not answered for more than ([\d.]+) s", line).group(1))
    assert limit == FLOOR_S, line
    stopped = float(re.search(r"rank 1 stops at ([\d.]+)", text).group(1))
    assert ended - stopped < FLOOR_S + 15, (ended - stopped, line)  # torchrun's exit included


def _rank_pids(parent: int) -> dict[int, int]:
    """rank -> pid of the workers a torchrun process started (read from /proc)."""
    out: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) != parent:
                continue
            env = (entry / "environ").read_bytes().split(b"\0")
        except (OSError, IndexError, ValueError):
            continue
        for item in env:
            if item.startswith(b"RANK="):
                out[int(item[5:])] = int(entry.name)
    return out


@pytest.mark.slow
def test_model_train_ends_when_rank_1_is_frozen_mid_run(tmp_path: Path, write_tiny_root) -> None:
    """The real command: ``torchrun -m model.train`` on two CPU ranks; once steps are logged,
    rank 1 is stopped (SIGSTOP) from outside. Rank 0 names rank 1 within the step-derived bound
    and torchrun ends (gloo alone would wait 30 minutes)."""
    import signal
    import subprocess
    import sys

    from tests.conftest import free_port

    root = write_tiny_root(tmp_path / "root", frames=3)
    out = tmp_path / "run"
    args = ["-m", "model.train", "--data", str(root), "--out", str(out), "--grounding", "tpcnet"]
    args += ["--train-split", "test", "--epochs", "10000", "--max-steps", "100000"]
    args += ["--batch-size", "1", "--val-every", "0", "--log-every", "1", "--device", "cpu"]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(REPO))
    env.pop("TALK2PC_RANK_TIMEOUT", None)
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nnodes", "1", "--nproc_per_node"]
    cmd += ["2", "--master_addr", "127.0.0.1", "--master_port", str(free_port()), *args]
    log = tmp_path / "torchrun.log"
    with open(log, "w") as handle:
        proc = subprocess.Popen(
            cmd, cwd=REPO, env=env, stdout=handle, stderr=handle, start_new_session=True
        )
        try:
            deadline = time.monotonic() + 240
            steps = out / "log.jsonl"
            while not (steps.is_file() and len(steps.read_text().splitlines()) >= 5):
                assert proc.poll() is None, log.read_text()[-3000:]
                assert time.monotonic() < deadline, log.read_text()[-3000:]
                time.sleep(0.2)
            ranks = _rank_pids(proc.pid)
            assert set(ranks) == {0, 1}, ranks
            os.kill(ranks[1], signal.SIGSTOP)
            stopped = time.monotonic()
            code = proc.wait(timeout=120)
            took = time.monotonic() - stopped
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
    text = log.read_text()
    lines = [line for line in text.splitlines() if line.startswith("error: rank")]
    assert code != 0 and len(lines) == 1, text[-3000:]
    assert lines[0].startswith(f"error: rank 1 (pid {ranks[1]} ") and "it was killed" in lines[0]
    limit = float(re.search(r"has not answered for more than ([\d.]+) s", lines[0]).group(1))
    assert FLOOR_S <= limit < STARTUP_LIMIT_S, lines[0]  # from the steps, not a fixed minute
    assert took < limit + 20, (took, lines[0])
