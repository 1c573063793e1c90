"""``python launch.py``: a server that cannot start is a one-line error and exit code 2 within
seconds, never a hang (issue 11); :class:`app.server.Talk2PCApp` never waits forever for viser."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from app.server import AppConfig, ServerStartError, Talk2PCApp, check_listen_address
from scenes.talk2radar.layout import LIDAR_FOLDER, VELODYNE, sample_dir
from tests.paths import REPO

LAUNCH_TIMEOUT = 90.0
"""Seconds before a launch counts as hung (the import of torch alone can take seconds on a busy
machine; a hang is forever)."""


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory: pytest.TempPathFactory, write_tiny_root) -> Path:
    return write_tiny_root(tmp_path_factory.mktemp("launch") / "root", frames=2)


def _launch(*args: str) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(
            [sys.executable, "launch.py", *args],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=LAUNCH_TIMEOUT,
            check=False,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"launch.py {' '.join(args)} hung for {LAUNCH_TIMEOUT:.0f} s")


def _error_line(proc: subprocess.CompletedProcess) -> str:
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("error: "), proc.stderr
    return last


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--port", "-1"), "port -1 is out of range"),
        (("--port", "70000"), "port 70000 is out of range"),
        (("--host", "192.0.2.1"), "address 192.0.2.1 cannot be bound"),  # TEST-NET-1: not ours
        (("--host", "no-such-host.invalid"), "cannot resolve"),
    ],
)
def test_a_server_that_cannot_start_exits_2(tiny_root: Path, args, message) -> None:
    start = time.monotonic()
    proc = _launch("--data", str(tiny_root), *args)
    assert message in _error_line(proc)
    assert proc.stderr.strip().count("\n") == 0  # checked before anything else: nothing else said
    assert time.monotonic() - start < LAUNCH_TIMEOUT


def test_a_split_where_no_frame_loads_exits_2(tmp_path: Path, write_tiny_root) -> None:
    root = write_tiny_root(tmp_path / "root", frames=2)
    for path in sample_dir(root / LIDAR_FOLDER, VELODYNE).iterdir():
        path.unlink()
        path.write_bytes(b"abc")  # not a multiple of 16 bytes
    proc = _launch("--data", str(root), "--port", "0")
    assert "no frame of split 'test' loads" in _error_line(proc)


@pytest.mark.parametrize(
    ("host", "port", "message"),
    [
        ("127.0.0.1", -1, "out of range"),
        ("127.0.0.1", 65536, "out of range"),
        ("127.0.0.1", True, "out of range"),
        ("192.0.2.1", 0, "cannot be bound"),
        ("a" * 300, 0, "host"),
        ("bad\0host", 0, "host"),
    ],
)
def test_check_listen_address(host, port, message) -> None:
    with pytest.raises(ServerStartError, match=message):
        check_listen_address(host, port)


def test_a_busy_port_is_no_error() -> None:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        check_listen_address("127.0.0.1", sock.getsockname()[1])  # viser takes the next port
    check_listen_address("127.0.0.1", 0)


def test_start_never_waits_forever_for_viser(tmp_path: Path, monkeypatch, write_tiny_root) -> None:
    """viser 1.1.1 blocks forever when its server thread dies before listening; whatever the
    cause, ``start`` gives up after ``start_timeout`` seconds."""
    import app.server as server_module

    release, stopped = threading.Event(), threading.Event()

    class StuckViser:
        def __init__(self, *args, **kwargs) -> None:
            release.wait()  # what viser does when its thread died

        def stop(self) -> None:
            stopped.set()

    monkeypatch.setattr(server_module.viser, "ViserServer", StuckViser)
    root = write_tiny_root(tmp_path / "root", frames=1)
    app = Talk2PCApp(root, model=object(), config=AppConfig(port=0, start_timeout=0.5))
    start = time.monotonic()
    try:
        with pytest.raises(ServerStartError, match=r"did not start listening .* within 0\.5 s"):
            app.start()
        assert time.monotonic() - start < 10.0
        release.set()  # a server that starts after the deadline is stopped at once
        assert stopped.wait(5.0)
    finally:
        release.set()
        app.stop()


# ---------------------------------------------------------------------------- every exit of main()


@pytest.fixture
def launch_main(capsys: pytest.CaptureFixture[str]):
    """``launch.main(argv)`` in this process: ``(exit code, last line on stderr)``."""
    import launch

    def run(*argv: str) -> tuple[int, str]:
        code = launch.main(list(argv))
        err = capsys.readouterr().err.strip().splitlines()
        return code, err[-1] if err else ""

    return run


def test_user_errors_are_one_line_and_exit_2(tiny_root: Path, tmp_path: Path, launch_main) -> None:
    not_a_root = tmp_path / "empty"
    not_a_root.mkdir()
    cases = [
        (("--data", str(tmp_path / "missing")), "no such folder"),
        (("--data", str(not_a_root)), str(not_a_root)),
        (("--data", str(tiny_root), "--split", "val"), "val"),
        (("--data", str(tiny_root), "--threads", "0"), "--threads must be >= 1, got 0"),
        (("--data", str(tiny_root), "--checkpoint", str(tmp_path / "no.pt")), "--checkpoint:"),
    ]
    for argv, message in cases:
        code, line = launch_main("--port", "0", *argv)
        assert code == 2, argv
        assert line.startswith("error: ") and message in line, (argv, line)


def test_a_corrupt_checkpoint_is_one_line(tiny_root: Path, tmp_path: Path, capsys) -> None:
    import launch

    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint")
    assert launch.main(["--data", str(tiny_root), "--port", "0", "--checkpoint", str(garbage)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: --checkpoint: ") and "\n" not in err, err


def test_cuda_without_cuda_exits_2(tiny_root: Path, launch_main) -> None:
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    code, line = launch_main("--data", str(tiny_root), "--port", "0", "--device", "cuda")
    assert code == 2 and line == "error: --device cuda: CUDA is not available on this machine"


def test_bad_flags_exit_2_with_usage() -> None:
    import launch

    for argv in (["--port", "eighty"], ["--device", "tpu"], ["--no-such-flag"]):
        with pytest.raises(SystemExit) as caught:
            launch.parse_args(argv)
        assert caught.value.code == 2, argv


def test_serves_then_stops_cleanly_on_sigterm(tiny_root: Path) -> None:
    """The success path: the URL is printed once the server listens; SIGTERM stops it, exit 0."""
    import signal

    proc = subprocess.Popen(
        [sys.executable, "launch.py", "--data", str(tiny_root), "--port", "0"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + LAUNCH_TIMEOUT
        line = ""
        while "is serving" not in line:
            assert time.monotonic() < deadline, "launch.py never said it is serving"
            line = proc.stdout.readline()
            assert line or proc.poll() is None, proc.stderr.read()
        assert f"serving 2 frames of {tiny_root} at http://127.0.0.1:" in line
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=LAUNCH_TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert out.strip().splitlines()[-1] == "Stopped." and "Traceback" not in err
