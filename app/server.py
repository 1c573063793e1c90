"""The app object: :class:`Talk2PCApp` serves one split of a Talk2Radar root with one model.

Shared by every browser: the viser server, the current frame (navigation is shared, see
:mod:`app.navigation`), the frame cache and the model engine (:class:`app.engine.GroundingEngine`:
worker pool, model lock, scene-feature cache). Per browser: a :class:`app.session.ClientSession`
with its own panel, boxes, heatmap, history and camera.

Lifecycle::

    app = Talk2PCApp(Talk2RadarRoot("data/default"), model, AppConfig(port=0))
    app.start()            # non-blocking: viser serves from a daemon thread
    print(app.url)         # port 0 binds a free port; app.port tells which
    ...
    app.stop()             # idempotent; frees the port

``start`` loads the first loadable frame, begins encoding it and warms the model up (both in the
background), so the first prompt pays neither the text encoder's loading nor the scene encoding.
"""

from __future__ import annotations

import logging
import threading
from concurrent.futures import Future
from concurrent.futures import wait as futures_wait
from dataclasses import dataclass, replace
from pathlib import Path

import viser

from app.engine import GroundingEngine, GroundingModel
from app.navigation import Frame, FrameStore, step_index
from app.scene_view import chase_pose
from app.session import ClientSession
from scenes.root import RootError, Talk2RadarRoot

log = logging.getLogger(__name__)

DEFAULT_SCORE_THRESHOLD = 0.3
"""Initial score threshold when the model does not say (``model.cfg.head.score_threshold``)."""


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
    """

    host: str = "127.0.0.1"
    port: int = 8080
    split: str = "test"
    title: str = "Talk2PC"
    model_note: str | None = None
    feature_cache_size: int = 8
    frame_cache_size: int = 4
    workers: int = 2
    warm_up: bool = True
    dark_mode: bool = True


class Talk2PCApp:
    """The viser app (see the module docstring).

    Args:
        root: A Talk2Radar root (or its path).
        model: The grounding model, in eval mode (``model.tpcnet.TPCNet``).
        config: Server and display settings.

    Raises:
        RootError: the root is not a Talk2Radar root, or the split is missing or empty.
    """

    def __init__(
        self,
        root: Talk2RadarRoot | str | Path,
        model: GroundingModel,
        config: AppConfig | None = None,
    ) -> None:
        self.config = config or AppConfig()
        if not isinstance(root, Talk2RadarRoot):
            root = Talk2RadarRoot(root)
        self.frames = FrameStore(root, self.config.split, self.config.frame_cache_size)
        self.engine = GroundingEngine(
            model, feature_cache_size=self.config.feature_cache_size, workers=self.config.workers
        )
        head = getattr(getattr(model, "cfg", None), "head", None)
        self.score_threshold = float(getattr(head, "score_threshold", DEFAULT_SCORE_THRESHOLD))
        self.model_note = self.config.model_note
        self.server: viser.ViserServer | None = None
        self.frame: Frame | None = None
        self.sessions: dict[int, ClientSession] = {}
        self._nav_lock = threading.RLock()
        self._startup: list[Future] = []

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
        """Load the first frame and start serving (non-blocking). Returns ``self``."""
        if self.server is not None:
            return self
        self.frame = self._first_frame()
        server = viser.ViserServer(
            host=self.config.host, port=self.config.port, label=self.config.title, verbose=False
        )
        server.gui.configure_theme(
            dark_mode=self.config.dark_mode, control_width="large", show_share_button=False
        )
        pose = chase_pose(self.frame.ground_z)
        server.initial_camera.position = pose.position
        server.initial_camera.look_at = pose.look_at
        server.initial_camera.up = pose.up
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(self._on_disconnect)
        self.server = server
        if self.config.warm_up:
            self._startup.append(self.engine.warm_up())
        self._startup.append(self.engine.prefetch(self.frame.sample, self.engine.modalities[0]))
        log.info("serving %d frames of %s at %s", len(self.frames), self.frames.root, self.url)
        return self

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
        with self._nav_lock:
            for session in self.sessions.values():
                session.close()
            self.sessions.clear()
        self.engine.close()
        if server is not None:
            server.stop()

    def __enter__(self) -> Talk2PCApp:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _first_frame(self) -> Frame:
        errors = []
        for index in range(len(self.frames)):
            try:
                return self.frames.load(index)
            except (RootError, OSError, ValueError) as exc:
                log.error("frame %d (%s) failed to load: %s", index, self.frames.ids[index], exc)
                errors.append(str(exc))
        raise RootError(f"no frame of split {self.frames.split!r} loads; first error: {errors[0]}")

    # ------------------------------------------------------------------ clients

    def _on_connect(self, client: viser.ClientHandle) -> None:
        with self._nav_lock:
            session = ClientSession(self, client)
            self.sessions[client.client_id] = session
            try:
                session.build_gui()
                if self.frame is not None:
                    session.show_frame(self.frame)
            except Exception as exc:
                session.report_error("The panel failed to build", exc)
        log.info("client %d connected (%d connected)", client.client_id, len(self.sessions))

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._nav_lock:
            session = self.sessions.pop(client.client_id, None)
        if session is not None:
            session.close()
        log.info("client %d disconnected", client.client_id)

    # ------------------------------------------------------------------ navigation (shared)

    def go_to(self, index: int, requester: ClientSession | None = None) -> Frame | None:
        """Show frame ``index`` in every browser; returns it, or None when it fails (the
        requesting browser gets a notification and keeps the current frame)."""
        with self._nav_lock:
            if not 0 <= index < len(self.frames):
                message = f"There are frames 1..{len(self.frames)}; {index + 1} does not exist."
                if requester is not None:
                    requester.notify("No such frame", message, color="yellow")
                    requester.reset_frame_number()
                return None
            if self.frame is not None and index == self.frame.index:
                return self.frame
            try:
                frame = self.frames.load(index)
            except Exception as exc:
                title = f"Could not load frame {index + 1} ({self.frames.ids[index]})"
                if requester is not None:
                    requester.report_error(title, exc)
                    requester.reset_frame_number()
                else:
                    log.error("%s: %s", title, exc)
                return None
            self.frame = frame
            sessions = list(self.sessions.values())
            for session in sessions:
                try:
                    session.show_frame(frame)
                except Exception as exc:
                    session.report_error("Could not draw the frame", exc)
            modalities = {s.query.selected_modality() for s in sessions if s.query is not None}
        for modality in modalities or {self.engine.modalities[0]}:
            self.engine.prefetch(frame.sample, modality)
        return frame

    def reload_frames(self) -> None:
        """Re-read the split (after samples were added to the root) and update every panel's
        frame count; the frame on screen stays."""
        with self._nav_lock:
            current = self.frame.sample_id if self.frame is not None else None
            self.frames.refresh()
            if current in self.frames.ids:
                index = self.frames.index_of(current)
                if self.frame is not None and index != self.frame.index:
                    self.frame = replace(self.frame, index=index)
            for session in list(self.sessions.values()):
                session.update_frame_count()

    def step(self, delta: int, requester: ClientSession | None = None) -> Frame | None:
        """Go ``delta`` frames forward (negative: back), wrapping around the split."""
        with self._nav_lock:
            current = self.frame.index if self.frame is not None else 0
            return self.go_to(step_index(current, delta, len(self.frames)), requester)
