"""The app object: :class:`Talk2PCApp` serves one split of a root with one model (a Talk2Radar
root, a View-of-Delft release or a nuScenes root with its Talk2Car commands: :mod:`app.serving.served`).

Shared by every browser, owned here: the viser server, the current frame and the frame cache
(:class:`app.serving.navigation.Navigator`: navigation is shared), the model engine
(:class:`app.engine.GroundingEngine`: worker pool, model lock, scene-feature cache) and the
annotation store with the open Annotate tabs (:class:`app.annotate_tab.AnnotationHub`). Per
browser: a :class:`app.session.ClientSession` with its own panel, boxes, heatmap, history and
camera; it subscribes to the navigator and gets the Annotate tab as an extra tab. Nothing here is
global: :meth:`Talk2PCApp.stop` forgets it all.

Lifecycle::

    app = Talk2PCApp(Talk2RadarRoot("data/default"), model, AppConfig(port=0))
    app.start()            # non-blocking: viser serves from a daemon thread
    print(app.url)         # port 0 binds a free port; app.port tells which
    ...
    app.stop()             # idempotent; frees the port

``start`` loads the first loadable frame, begins encoding it and warms the model up (both in the
background), so the first prompt pays neither the text encoder's loading nor the scene encoding.

``start`` never hangs: viser 1.1.1 waits forever when its server thread dies before it listens (a
port outside 0..65535, an address that is not this machine's), so the host and port are checked
first (:func:`check_listen_address`) and viser is started under a deadline
(:attr:`AppConfig.start_timeout`); both failures raise :class:`ServerStartError` (an ``OSError``).
A busy port is no failure: viser serves on the next free one, as before.

Hostile input: every message handler viser registers is wrapped (:mod:`app.guards`: forged GUI
values refused or clamped to the widget's range, one rate-limited warning line per connection,
never a traceback), and what a departed browser leaves is collected (:mod:`app.memory`).
"""

from __future__ import annotations

import errno
import logging
import socket
import threading
from collections.abc import Callable
from concurrent.futures import Future
from concurrent.futures import wait as futures_wait
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import viser

from app.annotate_tab import AnnotationHub, build_annotation_tab
from app.engine import GroundingEngine, GroundingModel, initial_threshold
from app.guards import InputWarnings, LogGuards, guard_client, guard_server
from app.keys import add_escape_leaves_fields
from app.memory import MemoryReaper, freeze_startup_objects
from app.serving.ground_truth import frame_objects
from app.serving.navigation import (
    Frame,
    FrameLoadError,
    FrameStore,
    NavigationError,
    Navigator,
)
from app.serving.served import ServedRoot, serve_root
from app.session import ClientSession, ExtraTab, SessionOptions
from app.view.scene_view import chase_pose
from model import model_classes
from scenes.utils.cli import option

if TYPE_CHECKING:
    from scenes.datasets.source import NuScenesSource, Talk2RadarRoot

log = logging.getLogger(__name__)

DEFAULT_SCORE_THRESHOLD = 0.3
"""Initial score threshold when the model does not say (see :func:`app.engine.initial_threshold`)."""

MAX_PORT = 65535
"""The highest TCP port."""


class ServerStartError(OSError):
    """The server cannot listen on the host and port asked for; the one-line message says why."""


def check_listen_address(host: str, port: int) -> None:
    """Check that viser can listen on ``host:port`` before starting it.

    ``port`` must be an integer in ``0..65535`` (0: any free port) and ``host`` must resolve to
    addresses of this machine that a socket can be bound to; a port that is merely busy passes
    (viser tries the next ones), one that may not be bound (e.g. below 1024 without privileges)
    does not.

    Raises:
        ServerStartError: with a one-line message naming the host or port.
    """
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= MAX_PORT:
        raise ServerStartError(f"port {port!r} is out of range: use 0..{MAX_PORT} (0: a free port)")
    if not isinstance(host, str):
        raise ServerStartError(f"host {host!r} is not a host name or an address")
    try:
        infos = socket.getaddrinfo(
            host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )
    except socket.gaierror as exc:
        raise ServerStartError(f"host {host!r}: cannot resolve it ({exc.strerror})") from exc
    except (UnicodeError, ValueError) as exc:  # e.g. a label over 63 characters, a NUL
        raise ServerStartError(f"host {host!r} is not a valid host name ({exc})") from exc
    seen = set()
    for family, kind, proto, _, address in infos:
        if (family, address[0]) in seen:
            continue
        seen.add((family, address[0]))
        for probe in (0, port) if port else (0,):
            sock = socket.socket(family, kind, proto)
            try:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                if family == socket.AF_INET6:
                    sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
                sock.bind((address[0], probe, *address[2:]))
            except OSError as exc:
                if probe and exc.errno == errno.EADDRINUSE:
                    continue  # busy: viser serves on the next free port
                what = f"address {address[0]}" if not probe else f"port {probe}"
                raise ServerStartError(
                    f"cannot listen on {host}:{port}: {what} cannot be bound "
                    f"({exc.strerror or exc})"
                    + ("; is it an address of this machine?" if not probe else "")
                ) from exc
            finally:
                sock.close()


@dataclass(frozen=True)
class AppConfig:
    """Settings of :class:`Talk2PCApp`.

    Attributes:
        host: Interface to bind (``127.0.0.1`` keeps it local; ``0.0.0.0`` serves the network).
        port: TCP port; 0 binds a free one (tests). viser tries the next ports when it is busy.
        split: ImageSets split to browse.
        title: Title of the control panel.
        model_note: A warning shown at the top of every panel (e.g. an untrained model).
        feature_cache_size: Encoded (frame, modality) pairs kept.
        frame_cache_size: Loaded frames kept.
        workers: Threads of the model worker pool.
        warm_up: Run one tiny prompt at start (loads the text encoder before the first user).
        dark_mode: viser's dark theme (points read better on it).
        start_timeout: Seconds :meth:`Talk2PCApp.start` waits for viser to listen before it
            raises :class:`ServerStartError`.
        pairs_root: Where the Annotate tab saves pairs (a Talk2Radar root, created by the
            first save; on a nuScenes root, Talk2Car commands in ``DIR/commands/``); None: the
            served root when it has prompts, else no saving (the tab suggests
            :func:`app.serving.served.default_pairs_root`, or ``<root>-talk2car``).
        freeze_startup: Freeze the objects alive at start before any browser connects
            (:func:`app.memory.freeze_startup_objects`: cheap collections after disconnects);
            process-wide, so for the process that serves (``launch.py``), not for tests.
        scene_labels: The View-of-Delft root with every object of the served frames (for a
            Talk2Radar root; a release opened directly is its own): the Query tab then offers
            "Candidates: Labelled boxes".
        talk2car: The folder of a nuScenes root's Talk2Car command files (``{split}_commands.json``;
            a nuScenes root served without it has no commands).
    """

    host: str = option("127.0.0.1", help="interface to bind (default %(default)s)")
    port: int = option(8080, help="port (default %(default)s; 0 = any free)")
    split: str = "test"
    title: str = "Talk2PC"
    model_note: str | None = None
    feature_cache_size: int = 8
    frame_cache_size: int = 4
    workers: int = 2
    warm_up: bool = True
    dark_mode: bool = True
    start_timeout: float = 20.0
    pairs_root: Path | None = option(
        None,
        flag="--pairs",
        metavar="PAIRS",
        help="where annotation saves prompt-to-box pairs, a Talk2Radar root created by the "
        "first save (on a nuScenes root: Talk2Car commands in PAIRS/commands/); default: the "
        "served root when it has prompts; a root without prompts is never written beside: "
        "without --pairs its pairs are not saved",
    )
    freeze_startup: bool = False
    scene_labels: Path | None = option(
        None,
        help="the View-of-Delft root whose label_2 lists every object of the served frames: the "
        "Query tab then offers Candidates: Labelled boxes (a VoD root opened directly is its own)",
    )
    talk2car: Path | None = option(
        None,
        metavar="CMDS",
        help="with a nuScenes root as --data: the folder holding its Talk2Car "
        "{split}_commands.json; each sample's commands are listed with their referred boxes and "
        "each file is a --split",
    )


class Talk2PCApp:
    """The viser app (see the module docstring).

    Args:
        root: A Talk2Radar root, a View-of-Delft release, a nuScenes root
            (:class:`scenes.datasets.source.NuScenesSource`, with ``config.talk2car``'s commands), or
            the path of one (the kind is chosen once: :func:`app.serving.served.serve_root`).
        model: The grounding model, in eval mode (``model.tpcnet.TPCNet``).
        config: Server and display settings.

    Raises:
        RootError: the root is not a root, or the split is missing or empty.
        scenes.nuscenes.tables.NuScenesError: a malformed nuScenes root or command file.
    """

    def __init__(
        self,
        root: Talk2RadarRoot | NuScenesSource | str | Path,
        model: GroundingModel,
        config: AppConfig | None = None,
    ) -> None:
        self.config = cfg = config or AppConfig()
        self.served: ServedRoot = serve_root(
            root,
            pairs=cfg.pairs_root,
            scene_labels=cfg.scene_labels,
            talk2car=cfg.talk2car,
            classes=model_classes(model),
        )
        """The kind of root served, chosen once (:mod:`app.serving.served`)."""
        self.navigator = Navigator(
            FrameStore(
                self.served.root,
                cfg.split,
                cfg.frame_cache_size,
                self.served.frame_notes,
                objects=partial(frame_objects, labelled=self.served.labelled.source()),
                commands=self.served.frame_commands,
            ),
            after_move=self._prefetch,
        )
        self.engine = GroundingEngine(
            model, feature_cache_size=self.config.feature_cache_size, workers=self.config.workers
        )
        self.score_threshold = initial_threshold(model, DEFAULT_SCORE_THRESHOLD)
        self.model_note = self.config.model_note
        self.labelled = self.served.labelled
        chooses = bool(getattr(model, "takes_labelled_candidates", False))
        self.labelled_boxes = self.labelled.boxes if self.labelled.available and chooses else None
        self.annotations = AnnotationHub(self.served)
        self.server: viser.ViserServer | None = None
        self.sessions: dict[int, ClientSession] = {}
        self.input_warnings = InputWarnings()
        """Forged or malformed browser messages, one rate-limited line per connection."""
        self.reaper = MemoryReaper()
        """Collects what departed browsers leave (see :mod:`app.memory`)."""
        self._log_guards = LogGuards(self.input_warnings)
        self._startup: list[Future] = []
        self._connected = False
        """Whether a browser ever connected (see :meth:`_freeze_if_alone`)."""

    @property
    def frames(self) -> FrameStore:
        """The frames of the split being served."""
        return self.navigator.frames

    @property
    def frame(self) -> Frame | None:
        """The frame on screen (shared by every browser; None before :meth:`start`)."""
        return self.navigator.frame

    # ------------------------------------------------------------------ lifecycle

    @property
    def port(self) -> int:
        """The bound port (after :meth:`start`)."""
        if self.server is None:
            raise RuntimeError("the app is not started")
        return self.server.get_port()

    @property
    def url(self) -> str:
        """``http://host:port`` to open in a browser."""
        host = self.config.host
        shown = "127.0.0.1" if host in ("0.0.0.0", "") else host
        return f"http://{shown}:{self.port}"

    def start(self) -> Talk2PCApp:
        """Load the first frame and start serving (non-blocking). Returns ``self``.

        Raises:
            ServerStartError: the host or port cannot be served (checked first), or viser did not
                listen within :attr:`AppConfig.start_timeout` seconds.
            RootError: no frame of the split loads.
        """
        if self.server is not None:
            return self
        check_listen_address(self.config.host, self.config.port)
        first = self.navigator.load_first()
        server = self._start_viser()
        server.gui.configure_theme(
            dark_mode=self.config.dark_mode, control_width="large", show_share_button=False
        )
        pose = chase_pose(first.ground_z)
        server.initial_camera.position = pose.position
        server.initial_camera.look_at = pose.look_at
        server.initial_camera.up = pose.up
        guard_server(server, self.input_warnings)
        self._log_guards.install(server)
        if self.config.freeze_startup:
            freeze_startup_objects()  # again after the warm-up (the text encoder), if alone
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(self._on_disconnect)
        self.server = server
        self.reaper.start()
        if self.config.warm_up:
            self._startup.append(self.engine.warm_up())
        self._startup.append(self.engine.prefetch(first.sample, self.engine.modalities[0]))
        if self.config.freeze_startup:
            self._startup[0].add_done_callback(lambda _: self._freeze_if_alone())
        log.info("serving %d frames of %s at %s", len(self.frames), self.frames.root, self.url)
        return self

    def _start_viser(self) -> viser.ViserServer:
        """``viser.ViserServer(...)`` under a deadline (it blocks forever when its server thread
        dies before listening); a server that starts after the deadline is stopped at once."""
        cfg = self.config
        state: dict[str, object] = {}
        lock = threading.Lock()

        def create() -> None:
            try:
                server = viser.ViserServer(
                    host=cfg.host, port=cfg.port, label=cfg.title, verbose=False
                )
            except BaseException as exc:
                with lock:
                    state["error"] = exc
                return
            with lock:
                late = "gave_up" in state
                state["server"] = server
            if late:
                server.stop()

        thread = threading.Thread(target=create, name="viser-start", daemon=True)
        thread.start()
        thread.join(cfg.start_timeout)
        with lock:
            if "server" not in state and "error" not in state:
                state["gave_up"] = True
        if "gave_up" in state:
            raise ServerStartError(
                f"the server did not start listening on {cfg.host}:{cfg.port} within "
                f"{cfg.start_timeout:g} s"
            )
        error = state.get("error")
        if isinstance(error, OSError):
            raise ServerStartError(f"cannot listen on {cfg.host}:{cfg.port}: {error}") from error
        if isinstance(error, BaseException):
            raise error
        return state["server"]  # type: ignore[return-value]

    def _freeze_if_alone(self) -> None:
        """Freeze what the warm-up made, unless a browser connected meanwhile (its session
        would never be collected)."""
        with self.navigator.lock:
            if not self._connected:
                freeze_startup_objects()

    def wait_ready(self, timeout: float | None = None) -> None:
        """Block until the start-up work (model warm-up, first scene encoding) is done.

        Raises:
            TimeoutError: after ``timeout`` seconds.
        """
        futures_wait(self._startup, timeout=timeout)
        if not all(f.done() for f in self._startup):
            raise TimeoutError(f"the model did not warm up within {timeout} s")

    def stop(self) -> None:
        """Stop serving and the worker pool (idempotent)."""
        server, self.server = self.server, None
        with self.navigator.lock:
            for session in self.sessions.values():
                self.navigator.unsubscribe(session)
                session.close()
            self.sessions.clear()
        self.annotations.close()
        self.engine.close()
        self.reaper.stop()
        if server is not None:
            server.stop()
            self._log_guards.remove()

    def __enter__(self) -> Talk2PCApp:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ clients

    def _extra_tabs(self) -> tuple[ExtraTab, ...]:
        build = partial(build_annotation_tab, hub=self.annotations)
        return (ExtraTab("Annotate", viser.Icon.PENCIL, build, name="annotation panel"),)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        guard_client(client, self.input_warnings)  # before any widget exists
        options = SessionOptions(
            model_note=self.model_note,
            score_threshold=self.score_threshold,
            labelled_boxes=self.labelled_boxes,
        )
        with self.navigator.lock:
            self._connected = True
            session = ClientSession(client, self.navigator, self.engine, options)
            self.sessions[client.client_id] = session
            self.navigator.subscribe(session)
            try:
                add_escape_leaves_fields(client.gui)
                session.build_gui(self._extra_tabs())
                if self.frame is not None:
                    session.show_frame(self.frame)
            except Exception as exc:
                session.report_error("The panel failed to build", exc)
        log.info("client %d connected (%d connected)", client.client_id, len(self.sessions))

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self.navigator.lock:
            session = self.sessions.pop(client.client_id, None)
            if session is not None:
                self.navigator.unsubscribe(session)
        if session is not None:
            session.close()
        self.input_warnings.forget(f"client {client.client_id}")
        self.reaper.schedule()
        log.info("client %d disconnected", client.client_id)

    # ------------------------------------------------------------------ navigation (shared)

    def go_to(self, index: int) -> Frame | None:
        """Show frame ``index`` in every browser; returns it, or None when it fails (logged; a
        browser's own moves go through :meth:`ClientSession.go_to`, which shows the error)."""
        return self._move(lambda: self.navigator.go_to(index))

    def step(self, delta: int) -> Frame | None:
        """Go ``delta`` frames forward (negative: back), wrapping around the split."""
        return self._move(lambda: self.navigator.step(delta))

    def reload_frames(self) -> None:
        """Re-read the split (after samples were added to the root) and update every panel's
        frame count; the frame on screen stays."""
        self.navigator.reload()

    @staticmethod
    def _move(move: Callable[[], Frame]) -> Frame | None:
        try:
            return move()
        except FrameLoadError as exc:
            log.error("%s: %s", exc.title, exc.cause)
        except NavigationError:
            pass
        return None

    def _prefetch(self, frame: Frame) -> None:
        """Start encoding a new frame for the modalities the browsers have selected."""
        with self.navigator.lock:
            sessions = list(self.sessions.values())
        modalities = {s.query.selected_modality() for s in sessions if s.query is not None}
        for modality in modalities or {self.engine.modalities[0]}:
            self.engine.prefetch(frame.sample, modality)
