"""Session-wide test settings and the fixtures several test modules share.

Torch runs with one intra-op thread in the test process: on a 2-core machine the suite's own
servers, browser and subprocesses share the cores, and torch's OpenMP pool with two threads slows
down many times over when a core is taken (see docs/PERFORMANCE.md's thread table), which turned
the overfit test's two minutes into a timeout on a loaded machine.

Fixtures (test modules take them by name; none imports another test module):

- ``write_tiny_root(path, frames=3, seed=0) -> path``: a tiny Talk2Radar root (flat ground, one
  car-sized cluster around ``gt_box`` per frame, sparse radar); ``gt_box``: that car's box.
- ``torch_threads(count)``: a context manager running torch with ``count`` threads.
- ``serve_app(root, model, **config)``: a context manager serving the app on a free port (started
  and warmed up; stopped on exit).
- ``untrained_model(grounding, **overrides)``: the small preset with weights drawn from a fixed
  seed (the same model every call), in eval mode, on either grounding path; ``grounding``: a
  module-scoped parameter, ``"tpcnet"`` (the paper's path) then ``"referent"`` (the shipped
  path), so that a module's app fixture taking it runs the module's tests on both paths.
- ``random_scene(seed=0) -> (lidar, radar)``: a random cloud of 3,000 LiDAR points ``(N, 4)``
  and 60 radar points ``(M, 7)`` (float32, LiDAR frame, 2-30 m ahead), for tests that only need
  some candidates.
- ``ws_client(port)``: a :class:`BrowserLikeClient` speaking viser's websocket protocol.
- ``chromium``: Debian's Chromium (the test skips without it); ``chromium_args``: its flags.
- ``torchrun(args, log, timeout)``: ``torchrun`` with 2 CPU processes on a free local port, output
  into the file ``log``; its exit code (the process group is killed if it outlives ``timeout``).
- ``nuscenes_root``: a tiny nuScenes root with Talk2Car commands (train, val) written by
  ``scenes.export_nuscenes``, a ``vehicle.truck`` added to every sample (read only).
- ``serve_nuscenes(split)``: a context manager serving ``nuscenes_root`` with its commands
  (the small untrained referent-path model).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import msgspec
import numpy as np
import pytest
import torch
import viser
import zstandard
from websockets.sync.client import connect

from model.checkpoint_meta import CheckpointMeta
from scenes.geometry.calib import vod_lidar_calibration, vod_radar_calibration
from scenes.talk2radar.root import Talk2RadarWriter
from tests.browser_helpers import CHROMIUM_ARGS, find_chromium
from tests.paths import REPO

_EXIT_STATUS: list[int] = []
_CACHE: list[str] = []


def pytest_configure(config: pytest.Config) -> None:
    """Every ``--freeze-scene`` run of the tests keeps its cache (:mod:`model.training.scene_store`)
    in a folder of this process, never in the user's ``~/.cache`` (subprocesses inherit it)."""
    _CACHE.append(tempfile.mkdtemp(prefix="talk2pc-test-cache-"))
    os.environ["TALK2PC_CACHE"] = _CACHE[-1]


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Remember the run's exit status for :func:`pytest_unconfigure`; remove the session's
    cache folder (:func:`pytest_configure`)."""
    _EXIT_STATUS.append(int(exitstatus))
    for folder in _CACHE:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config: pytest.Config) -> None:
    """Leave with the run's exit status once pytest has reported everything, without the
    interpreter's teardown. A full run starts dozens of servers, worker pools and torch thread
    pools in one process; once (1 run in 3 on a clean clone, after "1010 passed") a native
    thread still joinable at teardown aborted the process ("terminate called without an active
    exception"), turning a green run red. The tests' own cleanup has run by now; only the
    process teardown is skipped. The app itself is unaffected (it is not a pytest process)."""
    if not _EXIT_STATUS or os.environ.get("TALK2PC_TEST_FULL_TEARDOWN"):
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(_EXIT_STATUS[-1])


torch.set_num_threads(1)

GT_BOX = np.array([15.0, 2.0, -0.95, 4.2, 1.8, 1.5, 0.1])
"""The car of every tiny-root frame (frame ``i`` shifted by ``2 i`` metres along x)."""

TIMEOUT_SCALE = float(os.environ.get("TALK2PC_TEST_TIMEOUT_SCALE", "4"))
"""Multiplies every wait's timeout (``pump_until``); waits end as soon as their condition holds."""


# ---------------------------------------------------------------------------- tiny roots


def write_tiny_root(path: Path, frames: int = 3, seed: int = 0) -> Path:
    """A Talk2Radar root with ``frames`` test samples: a flat ground at z = -1.7, a car-sized
    cluster of points around :data:`GT_BOX` (its label), sparse radar with velocities."""
    rng = np.random.default_rng(seed)
    writer = Talk2RadarWriter(path)
    ids = []
    for i in range(frames):
        ground = np.c_[
            rng.uniform([1.0, -20.0], [50.0, 20.0], size=(4000, 2)),
            rng.normal(-1.7, 0.01, 4000),
            rng.uniform(0, 60, 4000),
        ]
        box = GT_BOX + np.array([i * 2.0, 0, 0, 0, 0, 0, 0])
        car = np.c_[
            rng.uniform(box[:3] - box[3:6] / 2, box[:3] + box[3:6] / 2, size=(600, 3)),
            rng.uniform(100, 255, 600),
        ]
        radar = np.c_[
            rng.uniform([2.0, -15.0, -1.5], [45.0, 15.0, 0.5], size=(80, 3)),
            rng.normal(5, 5, 80),
            rng.normal(0, 4, (80, 2)),
            -rng.integers(0, 5, 80),
        ]
        files = writer.write_sensors(
            f"f{i}",
            np.r_[ground, car].astype(np.float32),
            radar.astype(np.float32),
            vod_lidar_calibration(),
            vod_radar_calibration(),
        )
        ids.append(writer.write_sample(i, files, box[None], ["Car"], "the car about 15 m ahead"))
    writer.write_image_sets({"test": ids, "train": ids[:1]})
    return path


@contextlib.contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """Run with ``count`` torch CPU threads, as ``launch.py`` does (restored afterwards)."""
    old = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(old)


@contextlib.contextmanager
def serve_app(root: Path, model: object, timeout: float = 60.0, **config: object) -> Iterator:
    """The app serving ``root`` with ``model`` on a free port (``AppConfig(port=0, **config)``),
    started and warmed up; stopped on exit."""
    from app import AppConfig, Talk2PCApp

    app = Talk2PCApp(root, model, AppConfig(port=0, **config))  # type: ignore[arg-type]
    app.start()
    try:
        app.wait_ready(timeout=timeout)
        yield app
    finally:
        app.stop()


GROUNDINGS = ("tpcnet", "referent")
"""The two grounding paths (``model.config.ModelConfig.grounding``): the paper's, the shipped one."""


def untrained_model(
    grounding: str = "tpcnet",
    seed: int = 0,
    operating_threshold: float | None = None,
    **overrides: object,
):
    """``build_model("small", grounding=grounding, **overrides)`` in eval mode, its random
    weights drawn from ``seed`` (torch's global random state is left as it was), so that a test
    sees the same untrained model every run. ``operating_threshold``: stored as a calibrated
    checkpoint stores it (0: every candidate is an answer, for tests that draw answers whatever
    an untrained stage happens to score)."""
    from model import build_model

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = build_model("small", grounding=grounding, **overrides).eval()
    if operating_threshold is not None:
        model.checkpoint_metadata = CheckpointMeta(operating_threshold=operating_threshold)
    return model


def random_scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Random LiDAR ``(3000, 4)`` and radar ``(60, 7)`` points, float32, 2-30 m ahead."""
    rng = np.random.default_rng(seed)
    lidar = np.c_[rng.uniform([2, -10, -1.5], [30, 10, 0.5], (3000, 3)), rng.uniform(0, 1, 3000)]
    radar = np.c_[rng.uniform([2, -10, -1], [30, 10, 0.5], (60, 3)), rng.normal(0, 1, (60, 4))]
    return lidar.astype(np.float32), radar.astype(np.float32)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The files holding a slow test run first, then those holding a real-browser test (the
    order is otherwise kept): with a worker per core (``make test``) the long files start early
    instead of one worker ending the run alone on the last of them."""
    rank: dict[Path, int] = {}
    for item in items:
        kind = (
            0 if item.get_closest_marker("slow") else 1 if item.get_closest_marker("browser") else 2
        )
        rank[item.path] = min(rank.get(item.path, 2), kind)
    items.sort(key=lambda item: rank[item.path])


@pytest.fixture(name="random_scene", scope="session")
def _random_scene() -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    return random_scene


@pytest.fixture(name="untrained_model", scope="session")
def _untrained_model() -> Callable[..., torch.nn.Module]:
    return untrained_model


def untrained_nuscenes_app_model() -> torch.nn.Module:
    """A fresh untrained referent-path model of the ``nuscenes`` class set that answers every
    box (threshold 0): what the app tests serve to see the set's ten classes."""
    return untrained_model(
        "referent",
        text_encoder="gru",
        classes="nuscenes",
        head__score_threshold=0.0,
        operating_threshold=0.0,
    )


@pytest.fixture(name="untrained_nuscenes_app_model", scope="session")
def _untrained_nuscenes_app_model() -> Callable[[], torch.nn.Module]:
    return untrained_nuscenes_app_model


@pytest.fixture(name="grounding", scope="module", params=GROUNDINGS)
def _grounding(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture(name="write_tiny_root", scope="session")
def _write_tiny_root() -> Callable[..., Path]:
    return write_tiny_root


@pytest.fixture(name="gt_box", scope="session")
def _gt_box() -> np.ndarray:
    return GT_BOX.copy()


@pytest.fixture(name="torch_threads", scope="session")
def _torch_threads() -> Callable[[int], contextlib.AbstractContextManager[None]]:
    return torch_threads


@pytest.fixture(name="serve_app", scope="session")
def _serve_app() -> Callable[..., contextlib.AbstractContextManager]:
    return serve_app


# ---------------------------------------------------------------------------- torchrun


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def torchrun(args: list[str], log: Path, timeout: float) -> int:
    """Run ``torchrun --nproc_per_node 2 ARGS`` (one node, a free port on 127.0.0.1, one torch
    thread per process, the repository on ``PYTHONPATH``) with stdout and stderr into the file
    ``log`` (not pipes: two ranks write progress bars at once); its exit code. The process group
    is killed when it outlives ``timeout`` seconds, or whatever it left behind, so that no worker
    stays."""
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(REPO))
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nnodes", "1", "--nproc_per_node"]
    cmd += ["2", "--master_addr", "127.0.0.1", "--master_port", str(free_port()), *args]
    with open(log, "w") as handle:
        proc = subprocess.Popen(
            cmd,
            cwd=REPO,
            env=env,
            stdout=handle,
            stderr=handle,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        try:
            return proc.wait(timeout=timeout)
        finally:
            if proc.poll() is None:  # never leave the workers behind
                os.killpg(proc.pid, signal.SIGKILL)


@pytest.fixture(name="torchrun", scope="session")
def _torchrun() -> Callable[[list[str], Path, float], int]:
    return torchrun


# ---------------------------------------------------------------------------- websocket client


def _decode(frame: bytes) -> list[dict]:
    raw_len = int.from_bytes(frame[:8], "little")
    zstd_len = int.from_bytes(frame[8:16], "little")
    payload = zstandard.ZstdDecompressor().decompress(
        frame[16 : 16 + zstd_len], max_output_size=raw_len
    )
    return msgspec.msgpack.decode(payload)["messages"]


class BrowserLikeClient:
    """A websocket client that behaves like the viser web client, minus the rendering.

    It speaks viser 1.1.1's protocol (spec §7): it registers with a ``ViewerCameraMessage``, then
    sends ``GuiUpdateMessage`` s (typing, clicking, selecting), scene clicks and gizmo drags, and
    decodes the server's frames (``[u64 raw][u64 zstd][zstd(msgpack)][binary]``) to track the
    scene nodes, GUI labels, dropdown options, markdown and notifications.
    """

    def __init__(self, port: int) -> None:
        self.ws = connect(
            f"ws://127.0.0.1:{port}",
            subprotocols=[f"viser-v{viser.__version__}"],
            max_size=None,
        )
        self.nodes: dict[str, str] = {}  # scene node name -> message type
        self.visible: dict[str, bool] = {}
        self.gui: dict[str, str] = {}  # label -> uuid
        self.notifications: list[tuple[str, str]] = []
        self.markdown: dict[str, str] = {}  # uuid -> content
        self.options: dict[str, tuple[str, ...]] = {}  # uuid -> dropdown options
        self.owners: dict[str, str] = {}  # scene node name -> owner id
        self.messages: list[dict] = []
        self._send(
            {
                "type": "ViewerCameraMessage",
                "wxyz": [1.0, 0.0, 0.0, 0.0],
                "position": [-10.0, 0.0, 5.0],
                "fov": 1.0,
                "near": 0.01,
                "far": 1000.0,
                "image_height": 600,
                "image_width": 800,
                "look_at": [10.0, 0.0, 0.0],
                "up_direction": [0.0, 0.0, 1.0],
            }
        )

    def _send(self, message: dict) -> None:
        self.ws.send(msgspec.msgpack.encode(message))

    def _handle(self, m: dict) -> None:
        self.messages.append(m)
        kind = m["type"]
        if kind == "RemoveSceneNodeMessage":
            for name in [n for n in self.nodes if n == m["name"] or n.startswith(m["name"] + "/")]:
                del self.nodes[name]
        elif kind == "SetSceneNodeVisibilityMessage":
            self.visible[m["name"]] = m["visible"]
        elif "name" in m and kind.endswith("Message") and "props" in m:
            self.nodes[m["name"]] = kind
        if kind == "NotificationShowMessage":
            self.notifications.append((m["props"]["title"], m["props"]["body"]))
        props = m.get("props")
        if kind.startswith("Gui") and isinstance(props, dict) and props.get("label"):
            self.gui[props["label"]] = m["uuid"]
        if kind == "GuiMarkdownMessage":
            self.markdown[m["uuid"]] = props["_markdown"]
        updates = m.get("updates", {}) if kind == "GuiUpdateMessage" else {}
        if "_markdown" in updates:
            self.markdown[m["uuid"]] = updates["_markdown"]
        if kind == "GuiDropdownMessage":
            self.options[m["uuid"]] = tuple(props["options"])
        elif "options" in updates:
            self.options[m["uuid"]] = tuple(updates["options"])
        if "owner" in m and "name" in m:
            self.owners[m["name"]] = m["owner"]

    def pump_until(self, condition: Callable[[], bool], timeout: float, what: str) -> None:
        """Read messages until ``condition()`` holds; fail after ``timeout`` seconds, scaled by
        ``TIMEOUT_SCALE`` (a bound for a stalled server, not a speed check: a machine whose cores
        are busy with other jobs can be many times slower than an idle one)."""
        timeout *= TIMEOUT_SCALE
        deadline = time.monotonic() + timeout
        while not condition():
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"timed out after {timeout} s waiting for {what}")
            try:
                frame = self.ws.recv(timeout=min(left, 0.2))
            except TimeoutError:
                continue
            for m in _decode(frame):
                self._handle(m)

    def set(self, label: str, value: object) -> None:
        """Change an input as a user would (typing, selecting, dragging)."""
        self._send(
            {"type": "GuiUpdateMessage", "uuid": self.gui[label], "updates": {"value": value}}
        )

    def click(self, label: str, option: object = True) -> None:
        """Click a button (or one button of a button group)."""
        self.set(label, option)

    def dropdown(self, label: str) -> tuple[str, ...]:
        """The options of a dropdown."""
        return self.options[self.gui[label]]

    def click_ground(
        self, x: float, y: float, ground_z: float, modifier: str | None = None
    ) -> None:
        """A click on the ground point ``(x, y)`` seen from 10 m above the sensor (``modifier``:
        held with it, e.g. ``"shift"``)."""
        origin = np.array([0.0, 0.0, 10.0])
        direction = np.array([x, y, ground_z]) - origin
        direction /= np.linalg.norm(direction)
        self._send(
            {
                "type": "ScenePointerMessage",
                "event_type": "click",
                "ray_origin": origin.tolist(),
                "ray_direction": direction.tolist(),
                "screen_pos": [[0.5, 0.5]],
                "modifier": modifier,
            }
        )

    def drag_gizmo(
        self, name: str, poses: list[tuple[float, float, tuple[float, ...]]], z: float
    ) -> None:
        """Drag the transform gizmo ``name`` through ``(x, y, wxyz)`` poses, as one drag."""
        owner = self.owners[name]
        self._send({"type": "TransformControlsDragStartMessage", "name": name, "owner": owner})
        for x, y, wxyz in poses:
            self._send(
                {
                    "type": "TransformControlsUpdateMessage",
                    "name": name,
                    "wxyz": list(wxyz),
                    "position": [x, y, z],
                    "owner": owner,
                }
            )
        self._send({"type": "TransformControlsDragEndMessage", "name": name, "owner": owner})

    def drain(self, seconds: float) -> None:
        """Read whatever arrives during ``seconds``."""
        deadline = time.monotonic() + seconds
        self.pump_until(lambda: time.monotonic() >= deadline, seconds + 1.0, "nothing")

    def close(self) -> None:
        self.ws.close()


@pytest.fixture(name="ws_client", scope="session")
def _ws_client() -> Callable[[int], BrowserLikeClient]:
    return BrowserLikeClient


# ---------------------------------------------------------------------------- Chromium


@pytest.fixture(scope="session")
def chromium() -> str:
    """Debian's Chromium; the test skips (and says so) where there is none (session-scoped, so
    that a module's fixture can start one browser for its tests)."""
    path = find_chromium()
    if path is None:
        pytest.skip("no Chromium found (/usr/bin/chromium): install Debian's `chromium` package")
    return path


@pytest.fixture(name="chromium_args", scope="session")
def _chromium_args() -> list[str]:
    return list(CHROMIUM_ARGS)


# ---------------------------------------------------------------------------- View-of-Delft roots


@pytest.fixture(name="write_vod_root", scope="session")
def _write_vod_root() -> Callable[..., Path]:
    """``write_vod_root(path, frames=3, seed=0, radar_folder="radar", images=True, splits=None)``:
    a small root in the View-of-Delft release layout (:mod:`tests.vod_fixtures`)."""
    from tests.vod_fixtures import write_vod_root

    return write_vod_root


# ---------------------------------------------------------------------------- real-format roots

REAL_FORMAT_SOURCE = {"frames": 8, "seed": 11, "prompts_per_world": 2, "camera_scale": 0.25}
"""The synthetic root :func:`real_format_roots` exports: 4 worlds of 2 prompts each (train 2,
val 1, test 1), the camera at a quarter of VoD's size."""


@pytest.fixture(scope="session")
def real_format_source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny synthetic root (with its sidecars) that :func:`real_format_roots` exports
    (:data:`REAL_FORMAT_SOURCE`). Read only."""
    from scenes.synth.camera import CameraConfig
    from scenes.synth.generate import SynthSettings, generate_root

    spec = REAL_FORMAT_SOURCE
    settings = SynthSettings(
        seed=spec["seed"],
        prompts_per_world=spec["prompts_per_world"],
        camera=CameraConfig(image_scale=spec["camera_scale"]),
    )
    out = tmp_path_factory.mktemp("real-format") / "synth"
    generate_root(out, spec["frames"], settings, split_fractions=(0.5, 0.25, 0.25))
    return out


@pytest.fixture(scope="session")
def real_format_roots(real_format_source: Path) -> tuple[Path, Path]:
    """``(t2r_root, vod_root)``: :func:`real_format_source` as the real releases come
    (``python -m scenes.export_real --radar both``): a Talk2Radar tree with one prompt per frame,
    label_2 = its referents and no sidecar, and a View-of-Delft tree of the same 4 frame ids whose
    label_2 lists every annotated object under VoD's class names; both with the ``radar`` and
    ``radar_5frames`` trees. Read only (copy a root before changing it)."""
    from scenes.export_real import export

    base = real_format_source.parent
    export(real_format_source, base / "t2r", base / "vod", radar="both")
    return base / "t2r", base / "vod"


# ---------------------------------------------------------------------------- nuScenes roots

NUSCENES_SOURCE = {"frames": 16, "seed": 5, "prompts_per_world": 4, "camera_scale": 0.125}
"""The synthetic root :func:`nuscenes_root` exports: 4 worlds of 4 prompts (4 nuScenes samples,
10 single-referent commands: train 6, val 2, test 2)."""


@pytest.fixture(scope="session")
def nuscenes_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny nuScenes root with Talk2Car commands (``<root>/commands/{split}_commands.json``),
    exported by ``python -m scenes.export_nuscenes`` from :data:`NUSCENES_SOURCE` (about 4 s).
    Read only (copy it before changing it)."""
    from scenes.export_nuscenes import export
    from scenes.synth.camera import CameraConfig
    from scenes.synth.generate import SynthSettings, generate_root

    spec = NUSCENES_SOURCE
    settings = SynthSettings(
        seed=spec["seed"],
        prompts_per_world=spec["prompts_per_world"],
        camera=CameraConfig(image_scale=spec["camera_scale"]),
    )
    base = tmp_path_factory.mktemp("nuscenes")
    generate_root(base / "synth", spec["frames"], settings, split_fractions=(0.5, 0.25, 0.25))
    export(base / "synth", base / "nusc", seed=3)
    return base / "nusc"


@pytest.fixture(scope="session")
def serve_nuscenes(
    nuscenes_root: Path,
    tmp_path_factory: pytest.TempPathFactory,
    untrained_model: Callable[..., torch.nn.Module],
) -> Callable[[str], contextlib.AbstractContextManager]:
    """``serve_nuscenes(split)``: the app serving :func:`nuscenes_root` with its Talk2Car
    commands on ``split`` (the small referent-path TPCNet, GRU text, untrained, every proposal
    kept; pairs into a fresh folder; no warm-up), one torch thread; stopped on exit."""

    @contextlib.contextmanager
    def serve(split: str) -> Iterator:
        pairs = tmp_path_factory.mktemp("nusc-pairs") / "pairs"
        with torch_threads(1):
            model = untrained_model("referent", text_encoder="gru", head__score_threshold=0.0)
            config = {"talk2car": nuscenes_root / "commands", "pairs_root": pairs}
            with serve_app(nuscenes_root, model, split=split, warm_up=False, **config) as app:
                yield app

    return serve


@pytest.fixture(scope="session")
def nuscenes_training_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny nuScenes root written by ``python -m scenes.export_nuscenes``'s export (4 synthetic
    worlds, half train, half val; ``commands/{train,val}_commands.json``) with one parked
    ``vehicle.truck`` (outside the class set) added to every sample and the scene descriptions
    made "Rain, ..." and "Night, ..." in turn (:mod:`tests.nuscenes_fixtures`). Read only (copy it before changing it)."""
    from tests.nuscenes_fixtures import add_out_of_class, prefix_descriptions, write_nuscenes_root

    path = write_nuscenes_root(tmp_path_factory.mktemp("nuscenes") / "NUSC")
    add_out_of_class(path)
    prefix_descriptions(path)
    return path
