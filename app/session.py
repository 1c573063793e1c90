"""Per-browser state of the app: :class:`ClientSession`.

One session per viser client (websocket connection), created when the browser connects and closed
when it leaves. It coordinates; the concepts live in their packages: the Query tab in
:mod:`app.query` (the text read once at :meth:`ClientSession.run_prompt`, the one door, by
:func:`app.query.prompt.read_prompt`; the run, :mod:`app.query.request`; the answer drawn,
:class:`app.query.answer.AnswerView`), the 3D scene and the camera image in :mod:`app.view`,
the frames in :mod:`app.serving`. It owns that browser's GUI (``client.gui``) and scene nodes
(``client.scene``): points, ground-truth and predicted boxes, heatmap. It knows nothing of the app object: what every
browser shares comes in as the :class:`~app.serving.navigation.Navigator` (the current frame: the session
subscribes to its moves, :meth:`ClientSession.frame_shown`, and shows a failed move as a notification), the
:class:`~app.engine.GroundingEngine` (model, worker pool, scene-feature cache) and
:class:`SessionOptions`.

Threading: viser runs ``def`` callbacks in its thread pool, so callbacks of one browser may run
concurrently (with each other and with navigation). Model work goes to the engine's worker pool
(:meth:`GroundingEngine.submit <app.engine.GroundingEngine.submit>`); everything that draws into
this browser holds :attr:`ClientSession.lock`. Each prompt gets a generation number: an answer
that arrives after a newer prompt, a frame change or the browser leaving is dropped.

Extra tabs (the annotation mode): :meth:`ClientSession.build_gui` takes :class:`ExtraTab` s (the
app passes the Annotate tab, :func:`app.annotate_tab.build_annotation_tab`); each one's
``build(session)`` runs inside its tab, so the widgets it adds with ``session.client.gui`` land
there. What a tab may use:

- ``session.client`` (``client.gui``, ``client.scene`` for per-browser drafts and gizmos,
  ``client.camera``), ``session.navigator`` (``frames``: the :class:`~app.serving.navigation.FrameStore`
  and its ``root``; ``reload()`` after saving a sample into the root being served),
  ``session.go_to(i)`` (a move, its errors shown in this browser), ``session.engine``;
- ``session.frame`` / ``session.sample`` (the frame on screen), ``session.answer`` /
  ``session.predictions`` (the last answer drawn, or None);
- ``session.add_frame_listener(fn)`` and ``session.add_answer_listener(fn)``: ``fn(session)`` is
  called (in a worker thread, holding ``session.lock``) after a new frame or a new answer is drawn;
- ``session.notify(title, body)``, ``session.report_error(title, error)``: messages in this browser;
- ``session.lock``: hold it while drawing into ``client.scene`` from a worker thread;
- ``session.set_camera_layer(name, layer)``: boxes drawn into the camera panel
  (:class:`app.view.camera_panel.CameraPanel`, an :class:`app.view.camera_image.BoxLayer`; None removes
  them); the session itself draws the layers ``gt`` and ``pred``.

Scene-tree names used here (avoid them): ``/scene/...``, ``/pred/...``, ``/gt/...``, ``/heatmap``.
An exception raised by a tab's ``build`` is logged and shown in the tab; the app keeps running.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future

import viser

from app.engine import Answer, GroundingEngine, Predictions
from app.messages import error_body, notify
from app.query.answer import AnswerView
from app.query.panel import PromptField, QueryPanel, build_query_panel
from app.query.prompt import Prompt, Refused, read_prompt
from app.query.request import QueryRequest, answer_request
from app.serving.frame_commands import CommandList, command_in_play, command_objects
from app.serving.ground_truth import NO_OBJECTS, FrameObjects
from app.serving.navigation import (
    Frame,
    FrameLoadError,
    NavigationError,
    NavigationPanel,
    Navigator,
    build_navigation_panel,
)
from app.session_options import ExtraTab, SessionOptions
from app.text import md_text
from app.view.boxes_view import GroundTruthView
from app.view.camera_image import BoxLayer
from app.view.camera_panel import CameraPanel
from app.view.scene_view import SceneView, ViewPanel, build_view_panel
from scenes.frame import Sample

log = logging.getLogger(__name__)

Listener = Callable[["ClientSession"], None]


class ClientSession:
    """The state and the GUI of one browser (see the module docstring).

    Args:
        client: The browser's viser client handle.
        navigator: The shared current frame (the session subscribes to it when its GUI is built).
        engine: The model behind the app.
        options: What every session shows the same way.
    """

    def __init__(
        self,
        client: viser.ClientHandle,
        navigator: Navigator,
        engine: GroundingEngine,
        options: SessionOptions | None = None,
    ) -> None:
        self.client = client
        self.navigator = navigator
        self.engine = engine
        self.options = options or SessionOptions()
        self.lock = threading.RLock()
        self.frame: Frame | None = None
        self.answer: Answer | None = None
        self.last_latency_ms: float | None = None
        self.scene_view = SceneView(client.scene)
        self.answers = AnswerView(client.scene, engine.classes)
        """The answer on screen: boxes, heatmap, the prompts run, the summary."""
        self.pred_view = self.answers.boxes
        """The answer's boxes as drawn (``count``: how many)."""
        self.heatmap_view = self.answers.heatmap
        self.gt_view = GroundTruthView(client.scene, "/gt")
        self.nav: NavigationPanel | None = None
        self.commands: CommandList | None = None
        self.command: int | None = None
        """The frame's command in play (:mod:`app.serving.frame_commands`; None: none)."""
        self.objects: FrameObjects = NO_OBJECTS
        """The frame's labelled objects as drawn here (the command in play's referent marked)."""
        self.query: QueryPanel | None = None
        self.prompt_field: PromptField | None = None
        self.view: ViewPanel | None = None
        self.camera: CameraPanel | None = None
        self.tabs: dict[str, viser.GuiTabHandle] = {}
        """The extra tabs by label (see :meth:`build_gui`)."""
        self.closed = False
        self._generation = 0
        self._frame_listeners: list[Listener] = []
        self._answer_listeners: list[Listener] = []
        self._movers: set[int] = set()  # threads running a move this browser asked for

    # ------------------------------------------------------------------ public state

    @property
    def client_id(self) -> int:
        return self.client.client_id

    @property
    def sample(self) -> Sample | None:
        """The sample on screen."""
        return None if self.frame is None else self.frame.sample

    @property
    def predictions(self) -> Predictions | None:
        """The predictions drawn (``model.core.features.Predictions``), or None."""
        return None if self.answer is None else self.answer.predictions

    def add_frame_listener(self, fn: Listener) -> None:
        """Call ``fn(session)`` after each new frame is drawn."""
        self._frame_listeners.append(fn)

    def add_answer_listener(self, fn: Listener) -> None:
        """Call ``fn(session)`` after each answer is drawn."""
        self._answer_listeners.append(fn)

    # ------------------------------------------------------------------ messages

    def notify(
        self,
        title: str,
        body: str,
        *,
        color: str | None = None,
        auto_close_seconds: float | None = 6.0,
    ) -> None:
        """Show a notification in this browser (ignored once it has left)."""
        if not self.closed:
            notify(self.client, title, body, color=color, auto_close_seconds=auto_close_seconds)

    def report_error(self, title: str, error: BaseException | str) -> None:
        """Log an error and show it in this browser as a red notification."""
        body = error_body(self.client, title, error)
        self.notify(title, body, color="red", auto_close_seconds=12.0)

    # ------------------------------------------------------------------ GUI

    def build_gui(self, extra_tabs: Sequence[ExtraTab] = ()) -> None:
        """Create this browser's panel: note, Scene folder, Query / View tabs, then ``extra_tabs``."""
        gui = self.client.gui
        if self.options.model_note:
            gui.add_markdown(f"**Warning: {md_text(self.options.model_note)}**")
        with gui.add_folder("Scene"):
            self.nav = build_navigation_panel(gui, len(self.navigator))
            self.commands = CommandList(gui, self.run_command)
        tabs = gui.add_tab_group()
        shown = self.frame or self.navigator.frame  # the frame this panel will show first
        sample_prompt = (shown.sample.prompt or "") if shown is not None else ""
        with tabs.add_tab("Query", icon=viser.Icon.MESSAGE):
            self.query = build_query_panel(
                gui,
                self.engine.modalities,
                self.options.score_threshold,
                prompt=sample_prompt,
                labelled=self.options.labelled_boxes is not None,
            )
            self.prompt_field = PromptField(self.query.prompt)
        with tabs.add_tab("View", icon=viser.Icon.EYE):
            self.view = build_view_panel(gui, self.scene_view.settings, self.engine.classes.names)
        self.nav.wire(self.step, self.go_to)
        self._wire_query(self.query)
        self.camera = CameraPanel(gui, self.scene_view.settings.velocity_range)
        self.camera.wire(self.lock, lambda exc: self.report_error("Camera panel", exc))
        self.view.wire(self.scene_view, self.client, self.lock, self._ground_z, self.camera)
        for extra in extra_tabs:
            tab = tabs.add_tab(extra.label, icon=extra.icon)
            self.tabs[extra.label] = tab
            with tab:
                try:
                    extra.build(self)
                except Exception as exc:
                    log.exception("the %s failed to build", extra.name)
                    gui.add_markdown(
                        f"The {md_text(extra.name)} failed: "
                        f"{md_text(f'{type(exc).__name__}: {exc}')}"
                    )

    def _wire_query(self, q: QueryPanel) -> None:
        q.wire_prompts(self.run_prompt, self.write_prompt, lambda: self.sample, self._rerun_last)
        q.wire_layers(
            self.lock,
            self.answers.heatmap,
            self.gt_view,
            lambda gt, others: self._with_camera(lambda camera: camera.show_gt(gt, others)),
        )

    def _rerun_last(self) -> None:
        """A setting changed: run the last prompt again (none yet: encode the frame for it)."""
        if self.answer is not None:
            self._ask(Prompt(self.answer.prompt))  # read when it entered: run as it is
        elif self.sample is not None and self.query is not None:
            self.engine.prefetch(self.sample, self.query.selected_modality())

    @property
    def others_visible(self) -> bool:
        """Whether *Other annotations* shows the labelled objects that are not referents."""
        return self.query is None or bool(self.query.show_others.value)

    # ------------------------------------------------------------------ frames

    def _ground_z(self) -> float:
        return self.frame.ground_z if self.frame is not None else self.scene_view.ground_z

    def _with_camera(self, fn: Callable[[CameraPanel], None]) -> None:
        """``fn(camera panel)`` holding the lock; an error becomes a notification."""
        try:
            with self.lock:
                if self.camera is not None and not self.closed:
                    fn(self.camera)
        except Exception as exc:
            self.report_error("Camera panel", exc)

    def set_camera_layer(self, name: str, layer: BoxLayer | None) -> None:
        """Draw ``layer`` (None: nothing) as the camera panel's box layer ``name`` (see
        :data:`app.view.camera_panel.LAYER_ORDER`); redrawn only when it changed."""
        self._with_camera(lambda camera: camera.set_layer(name, layer))

    def frame_shown(self, frame: Frame) -> None:
        """The shared frame moved (called by the navigator on the moving thread): draw it here;
        a failure is shown in this browser. Its own moves may fill the prompt box."""
        try:
            self.show_frame(frame, own_move=threading.get_ident() in self._movers)
        except Exception as exc:
            self.report_error("Could not draw the frame", exc)

    def show_frame(self, frame: Frame, own_move: bool = True) -> None:
        """Draw ``frame``: points, its labelled objects, the sample's prompt offered to the prompt box
        (:meth:`PromptField.offer`); the previous answer is cleared."""
        with self.lock:
            if self.closed:
                return
            self._generation += 1
            self.frame = frame
            self.answer = None
            sample = frame.sample
            with self.client.atomic():
                self.scene_view.show(sample.lidar, sample.radar, frame.ground_z)
                self.answers.clear()
                if self.commands is not None:
                    self.commands.show(frame.commands, 0 if frame.commands else None)
                self._mark_command(0 if frame.commands else None, camera=False)
                if self.query is not None:
                    self.gt_view.visible = self.query.show_gt.value
                    self.gt_view.others_visible = self.query.show_others.value
                    if self.prompt_field is not None:
                        self.prompt_field.offer(sample.prompt or "", own_move)
                    self.query.use_frame_prompt.disabled = not sample.prompt
                    self.query.results.content = "*Type a prompt and press Enter.*"
                if self.nav is not None:
                    self.nav.show(frame, len(self.navigator))
            objects = self.objects if frame.commands is not None else None
            self._with_camera(lambda camera: camera.show_frame(sample, objects))
            self._call(self._frame_listeners)

    def _mark_command(self, index: int | None, camera: bool = True) -> None:
        """Make command ``index`` of the frame on screen the one in play (holding :attr:`lock`):
        its referent drawn apart, its button marked (``camera``: the camera image too)."""
        frame = self.frame
        if frame is None:
            return
        commands = frame.commands
        self.command = index
        self.objects = (
            command_objects(frame.objects, commands[index])
            if commands and index is not None and index > 0
            else frame.objects  # (a frame's objects are marked for its first command)
        )
        self.gt_view.show(self.objects)
        if self.commands is not None:
            self.commands.mark(index)
        if camera and commands is not None:
            self._with_camera(lambda panel: panel.show_objects(self.objects))

    def split_changed(self) -> None:
        """Refresh the navigation widgets after the split was re-read (called by the navigator)."""
        with self.lock:
            if self.nav is None:
                return
            self.nav.set_count(len(self.navigator))
            if self.navigator.frame is not None:
                self.frame = self.navigator.frame
                self.nav.show(self.frame, len(self.navigator))

    def go_to(self, index: int) -> Frame | None:
        """Show frame ``index`` in every browser; returns it, or None when it fails (this browser
        gets a notification and its frame number box goes back to the frame shown)."""
        return self._move(lambda: self.navigator.go_to(index))

    def step(self, delta: int) -> Frame | None:
        """Go ``delta`` frames forward (negative: back) in every browser, as :meth:`go_to`."""
        return self._move(lambda: self.navigator.step(delta))

    def _move(self, move: Callable[[], Frame]) -> Frame | None:
        thread = threading.get_ident()
        self._movers.add(thread)
        try:
            return move()
        except FrameLoadError as exc:
            self.report_error(exc.title, exc.cause)
        except NavigationError as exc:
            self.notify(exc.title, str(exc), color="yellow")
        finally:
            self._movers.discard(thread)
        self.reset_frame_number()
        return None

    def reset_frame_number(self) -> None:
        """Put the frame number box back on the frame shown (after a failed jump)."""
        with self.lock:
            if self.nav is not None and self.frame is not None:
                self.nav.frame_number.value = self.frame.index + 1

    # ------------------------------------------------------------------ prompts

    def write_prompt(self, text: str) -> None:
        """Put ``text`` into this browser's prompt box (in reply to its own action)."""
        with self.lock:
            if self.prompt_field is not None and not self.closed:
                self.prompt_field.write(text)

    def run_command(self, index: int) -> Future | None:
        """Run command ``index`` of the frame on screen as if typed into the prompt box and run
        (:mod:`app.serving.frame_commands`); it becomes the command in play."""
        with self.lock:
            commands = self.frame.commands if self.frame is not None else None
            if not commands or not 0 <= index < len(commands) or self.closed:
                return None
            self._mark_command(index)
        return self.run_prompt(commands[index].text, write=True)

    def run_prompt(self, typed: str | None, write: bool = False) -> Future | None:
        """The one door of the Query tab's text (Enter, *Run*, *Re-run*, a frame's command): read
        once (:func:`app.query.prompt.read_prompt`: the text policy) and answered on the frame on
        screen, in the engine's worker pool; a text it refuses, or an empty one, gets a
        notification and clears the answer shown. ``write``: the prompt box shows the prompt as
        run (when refused: as typed, line breaks and runs of spaces made one). Returns the job's
        future (or None)."""
        received = time.perf_counter()
        prompt = read_prompt(typed)
        if write:
            self.write_prompt(prompt.shown if isinstance(prompt, Refused) else prompt)
        if isinstance(prompt, Refused):  # the previous answer goes too (not left as this one's)
            self.notify(prompt.title, prompt.body, color="yellow")
            self.clear_answer(f"*Not run:* {md_text(prompt.body)}")
            return None
        return self._ask(prompt, received)

    def _ask(self, prompt: Prompt, received: float | None = None) -> Future | None:
        """Answer ``prompt`` (read already: run as it is) with the Query tab's settings."""
        received = time.perf_counter() if received is None else received
        with self.lock:
            if self.frame is None or self.query is None or self.closed:
                return None
            found = command_in_play(self.frame.commands, self.command, prompt)
            if found != self.command:
                self._mark_command(found)
            self._generation += 1
            request = QueryRequest.of(self.query, prompt, self.frame, self._generation, received)
            self.query.results.content = f"*Running:* {md_text(prompt)}"
        self.client.flush()  # viser sends only a widget's latest value: a fast answer hid the line
        return self.engine.submit(self._answer_job, request)

    def clear_answer(self, note: str) -> None:
        """Remove the answer shown (boxes, heatmap, camera boxes; one still running is dropped)
        and say ``note`` (markdown) in its place."""
        with self.lock:
            if self.closed or self.query is None:
                return
            self._generation += 1
            self.answer = None
            with self.client.atomic():
                self.answers.clear()
                self.query.results.content = note
            self._with_camera(lambda camera: camera.set_layer("pred", None))
            self._call(self._answer_listeners)

    def _stale(self, request: QueryRequest) -> bool:
        return self.closed or request.generation != self._generation

    def _answer_job(self, request: QueryRequest) -> None:
        if self._stale(request):
            return
        try:
            answer = answer_request(self.engine, request, self.options.labelled_boxes)
        except Exception as exc:
            self.report_error("Model error", exc)
            with self.lock:
                if not self._stale(request) and self.query is not None:
                    self.query.results.content = f"*The model failed on:* {md_text(request.prompt)}"
            return
        with self.lock:
            if self._stale(request):
                return
            try:
                self._draw_answer(answer, request)
            except Exception as exc:
                self.report_error("Could not draw the answer", exc)
                return
            self._call(self._answer_listeners)

    def _draw_answer(self, answer: Answer, request: QueryRequest) -> None:
        """Draw the answer (:meth:`AnswerView.draw <app.query.answer.AnswerView.draw>`; holding
        :attr:`lock`)."""
        assert self.query is not None

        def drawn() -> None:
            self.answer = answer
            self._with_camera(lambda camera: camera.show_predictions(answer.predictions))

        latency = self.answers.draw(self.client, self.query, answer, request, self.objects, drawn)
        self.last_latency_ms = latency
        log.info(
            "client %s: %r on %s -> %d boxes in %.0f ms",
            self.client_id,
            request.prompt,
            answer.sample_id,
            len(answer.predictions.scores),
            latency,
        )

    # ------------------------------------------------------------------ lifecycle

    def _call(self, listeners: list[Listener]) -> None:
        for fn in listeners:
            try:
                fn(self)
            except Exception as exc:
                self.report_error("An extension failed", exc)

    def close(self) -> None:
        """Forget this browser (it disconnected): pending answers are dropped. What it held is
        collected soon after (:class:`app.memory.MemoryReaper`; the answer stays readable)."""
        with self.lock:
            self.closed = True
            self._generation += 1
