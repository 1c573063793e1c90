"""Issue 50 item 5, first half: one writer per run folder.

``model.train``, ``model.adapt`` and ``model.calibrate`` hold ``<folder>/run.lock``
(:mod:`scenes.utils.run_lock`): a second process on the same folder is refused with one line
naming the holder (pid, command, since when), a lock left by a process that is gone is taken
over with one line, and two processes racing for one folder never both get it.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from scenes.utils.run_lock import LOCK_FILE, RunLockError, read_holder, run_lock
from tests.paths import REPO

HOLD = """
import sys, time
from scenes.utils.run_lock import run_lock
with run_lock(sys.argv[1]):
    print("held", flush=True)
    time.sleep(float(sys.argv[2]))
"""


def _holder(folder: Path, seconds: float = 60.0) -> subprocess.Popen:
    """A process that holds ``folder``'s lock for ``seconds`` (started once it says so)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(folder), str(seconds), "--marker-arg"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        text=True,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
    return proc


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=30)


def test_a_second_process_is_refused_naming_the_holder(tmp_path: Path) -> None:
    folder = tmp_path / "run"
    proc = _holder(folder)
    try:
        holder = read_holder(folder)
        assert holder is not None and holder.pid == proc.pid
        assert holder.host == socket.gethostname() and "--marker-arg" in holder.command
        with pytest.raises(RunLockError) as info, run_lock(folder):
            pytest.fail("the lock of a live process was taken")
        line = str(info.value)
        assert "\n" not in line
        assert f"{folder} is in use by pid {proc.pid} on {socket.gethostname()} since " in line
        assert holder.started in line and "--marker-arg" in line
    finally:
        _stop(proc)


def test_a_stale_lock_is_taken_over_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """The holder killed outright (kill -9): its lock file stays, and the next run takes it over
    with one line naming the gone process; a hand-written lock of a dead pid is stale too."""
    folder = tmp_path / "run"
    proc = _holder(folder)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert (folder / LOCK_FILE).is_file()  # left behind
    with run_lock(folder):
        holder = read_holder(folder)
        assert holder is not None and holder.pid == os.getpid()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"took over the stale lock of pid {proc.pid}" in err[0], err
    assert not (folder / LOCK_FILE).exists() and folder.is_dir()  # released
    gone = subprocess.Popen(["true"])
    gone.wait()
    record = {"pid": gone.pid, "host": socket.gethostname(), "started": "x", "command": "old"}
    (folder / LOCK_FILE).write_text(json.dumps(record))
    with run_lock(folder):
        pass
    assert f"took over the stale lock of pid {gone.pid}" in capsys.readouterr().err


def test_a_lock_file_naming_a_live_process_is_not_taken(tmp_path: Path) -> None:
    """A lock file naming a live process of this host (or a process of another host, which
    cannot be checked) is not stale, even without its flock."""
    folder = tmp_path / "run"
    folder.mkdir()
    sleeper = subprocess.Popen(["sleep", "60"])
    try:
        for pid, host in ((sleeper.pid, socket.gethostname()), (1, "another-host")):
            command = "model.train\n--out X\u202e"  # a lock file is anybody's text
            record = {"pid": pid, "host": host, "started": "t0", "command": command}
            (folder / LOCK_FILE).write_text(json.dumps(record))
            refused = pytest.raises(RunLockError, match=f"in use by pid {pid} on {host} since t0")
            with refused as info, run_lock(folder):
                pytest.fail("a live holder's lock was taken")
            line = str(info.value)
            assert "(model.train --out X\\u202e)" in line and "\n" not in line, line
    finally:
        sleeper.kill()
        sleeper.wait()


def test_two_processes_racing_for_one_folder_one_wins(tmp_path: Path) -> None:
    """Eight processes started at once on one folder: exactly one holds it at a time (the
    winner holds it until every other has tried, however slowly a loaded machine starts them)."""
    folder = tmp_path / "run"
    tried = tmp_path / "tried"
    tried.mkdir()
    code = """
import os, sys, time
from pathlib import Path
from scenes.utils.run_lock import RunLockError, run_lock
time.sleep(max(0.0, float(sys.argv[2]) - time.time()))
tried = Path(sys.argv[3])
try:
    with run_lock(sys.argv[1]):
        print("won", flush=True)
        (tried / str(os.getpid())).touch()
        deadline = time.time() + 50
        while len(list(tried.iterdir())) < 8 and time.time() < deadline:
            time.sleep(0.05)
except RunLockError as exc:
    print("refused", exc, flush=True)
    (tried / str(os.getpid())).touch()
"""
    start = time.time() + 1.5
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", code, str(folder), str(start), str(tried)],
            cwd=REPO,
            stdout=subprocess.PIPE,
            text=True,
            env=dict(os.environ, PYTHONPATH=str(REPO)),
        )
        for _ in range(8)
    ]
    outs = [p.communicate(timeout=60)[0] for p in procs]
    assert sum(o.startswith("won") for o in outs) == 1, outs
    assert sum(o.startswith("refused") for o in outs) == 7, outs


def test_train_adapt_and_calibrate_refuse_a_folder_in_use(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """The real commands: each exits 2 with one line naming the live holder and writes
    nothing into the folder."""
    from model.adapt.__main__ import main as adapt_main
    from model.training.calibrate import main as calibrate_main
    from model.training.loop import main as train_main

    folder = tmp_path / "run"
    proc = _holder(folder)
    checkpoint = folder / "last.pt"
    try:
        runs = {
            "train": lambda: train_main(["--data", str(tmp_path), "--out", str(folder)]),
            "adapt": lambda: adapt_main(
                ["--data", str(tmp_path), "--init", str(checkpoint), "--out", str(folder)]
            ),
            "calibrate": lambda: calibrate_main(
                ["--data", str(tmp_path), "--checkpoint", str(checkpoint)]
            ),
        }
        for name, run in runs.items():
            assert run() == 2, name
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1, (name, err)
            assert err[0].startswith(f"error: {folder} is in use by pid {proc.pid} "), err
            assert "--marker-arg" in err[0]
            assert sorted(p.name for p in folder.iterdir()) == [LOCK_FILE], name
    finally:
        _stop(proc)


def test_a_stale_lock_whose_pid_was_given_again_is_taken_over(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """The holder was killed and its pid now names another live process of this host (one
    started after the lock was taken): the lock is stale, taken over with one line; a live
    process that started before the lock's time is still its holder."""
    import datetime

    folder = tmp_path / "run"
    folder.mkdir()
    sleeper = subprocess.Popen(["sleep", "60"])
    try:
        now = datetime.datetime.now().astimezone()
        for started, taken in ((now - datetime.timedelta(hours=1), True), (now, False)):
            record = {
                "pid": sleeper.pid,
                "host": socket.gethostname(),
                "started": started.isoformat(timespec="seconds"),
                "command": "model.adapt --out run",
            }
            (folder / LOCK_FILE).write_text(json.dumps(record))
            if taken:
                with run_lock(folder):
                    assert read_holder(folder).pid == os.getpid()
                err = capsys.readouterr().err
                assert f"took over the stale lock of pid {sleeper.pid}" in err
            else:
                refused = pytest.raises(RunLockError, match=f"in use by pid {sleeper.pid}")
                with refused, run_lock(folder):
                    pytest.fail("a live holder's lock was taken")
    finally:
        sleeper.kill()
        sleeper.wait()


def test_a_lock_file_that_is_a_link_is_not_followed(tmp_path: Path) -> None:
    """``run.lock`` made a link to another file: refused (an OSError naming it), the file it
    points to neither truncated nor written."""
    folder = tmp_path / "run"
    folder.mkdir()
    precious = tmp_path / "precious.txt"
    precious.write_text("mine\n")
    (folder / LOCK_FILE).symlink_to(precious)
    with pytest.raises(OSError, match=LOCK_FILE), run_lock(folder):
        pytest.fail("the lock was taken through a link")
    assert precious.read_text() == "mine\n" and (folder / LOCK_FILE).is_symlink()
