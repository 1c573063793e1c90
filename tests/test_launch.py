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
from tests.test_app_ws import write_tiny_root

REPO = Path(__file__).resolve().parents[1]

LAUNCH_TIMEOUT = 90.0
"""Seconds before a launch counts as hung (the import of torch alone can take seconds on a busy
machine; a hang is forever)."""


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
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


def test_a_split_where_no_frame_loads_exits_2(tmp_path: Path) -> None:
    root = write_tiny_root(tmp_path / "root", frames=2)
    for path in (root / "lidar" / "training" / "velodyne").iterdir():
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


def test_start_never_waits_forever_for_viser(tmp_path: Path, monkeypatch) -> None:
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
