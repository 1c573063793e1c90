"""Per-browser state of the app: :class:`ClientSession`.

One session per viser client (websocket connection), created when the browser connects and closed
when it leaves. It owns that browser's GUI (``client.gui``) and scene nodes (``client.scene``):
points, ground-truth and predicted boxes, heatmap. What is shared by every browser lives in the
app (:class:`app.server.Talk2PCApp`): the current frame (navigation is shared), the model and its
scene-feature cache.

Threading: viser runs ``def`` callbacks in its thread pool, so callbacks of one browser may run
concurrently (with each other and with the app's navigation). Model work goes to the engine's
worker pool (:meth:`GroundingEngine.submit <app.engine.GroundingEngine.submit>`); everything that
draws into this browser holds :attr:`ClientSession.lock`. Each prompt gets a generation number:
an answer that arrives after a newer prompt, a frame change or the browser leaving is dropped.

Extension point (the annotation mode)
-------------------------------------
If a module ``app.annotation_panel`` exists, every session calls its
``build_annotation_tab(session: ClientSession) -> None`` inside the context of an "Annotate" tab,
so the widgets it adds with ``session.client.gui`` land in that tab; nothing in this package has
to change. What it may use:

- ``session.client`` (the :class:`viser.ClientHandle`: ``client.gui``, ``client.scene`` for
  per-browser drafts and gizmos, ``client.camera``), ``session.app`` (``app.server``,
  ``app.frames``: the :class:`~app.navigation.FrameStore` and its ``root``, ``app.engine``;
  ``app.reload_frames()`` after saving a sample into the root being served, ``app.go_to(i)``);
- ``session.frame`` / ``session.sample`` (the frame on screen), ``session.answer`` /
  ``session.predictions`` (the last answer drawn, or None);
- ``session.add_frame_listener(fn)`` and ``session.add_answer_listener(fn)``: ``fn(session)`` is
  called (in a worker thread, holding ``session.lock``) after a new frame or a new answer is drawn;
- ``session.notify(title, body)``, ``session.report_error(title, error)``: messages in this browser;
- ``session.lock``: hold it while drawing into ``client.scene`` from a worker thread.

Scene-tree names used here (avoid them): ``/scene/...``, ``/pred/...``, ``/gt/...``, ``/heatmap``.
An exception raised by ``build_annotation_tab`` is logged and shown in the tab; the app keeps
running.
"""

from __future__ import annotations

import importlib
import importlib.util
import logging
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import viser

from app.boxes_view import GT_STYLE, PRED_STYLE, BoxesView, best_iou, box_label
from app.engine import Answer, Modality
from app.heatmap_view import HeatmapView
from app.navigation import (
    PREVIOUS,
    Frame,
    NavigationPanel,
    build_navigation_panel,
    frame_markdown,
)
from app.query_panel import (
    NO_HISTORY,
    PromptHistory,
    QueryPanel,
    build_query_panel,
    normalise_prompt,
    results_markdown,
    submitted_prompt,
)
from app.scene_view import (
    SceneView,
    ViewPanel,
    apply_pose,
    bev_pose,
    build_view_panel,
    chase_pose,
)
from app.text import md_text
from scenes.root import Sample

if TYPE_CHECKING:
    from app.server import Talk2PCApp

log = logging.getLogger(__name__)

ANNOTATION_MODULE = "app.annotation_panel"
"""Module whose ``build_annotation_tab(session)`` fills the "Annotate" tab, when it exists."""

EXAMPLE_PROMPT = "the car about 15 metres ahead"
"""Suggested in the empty-prompt notification."""

Listener = Callable[["ClientSession"], None]


@dataclass(frozen=True)
class QueryRequest:
    """One prompt to answer.

    Attributes:
        prompt: Normalised, non-empty prompt.
        modality: Sensors to use.
        score_threshold: Decoder threshold.
        frame: The frame on screen when the prompt was sent.
        generation: The session's generation number at that moment.
        received: ``time.perf_counter()`` when the server received the prompt.
    """

    prompt: str
    modality: Modality
    score_threshold: float
    frame: Frame
    generation: int
    received: float


class ClientSession:
    """The state and the GUI of one browser (see the module docstring).

    Args:
        app: The app (shared state: frames, engine, server).
        client: The browser's viser client handle.
    """

    def __init__(self, app: Talk2PCApp, client: viser.ClientHandle) -> None:
        self.app = app
        self.client = client
        self.lock = threading.RLock()
        self.frame: Frame | None = None
        self.answer: Answer | None = None
        self.last_latency_ms: float | None = None
        self.history = PromptHistory()
        self.scene_view = SceneView(client.scene)
        self.pred_view = BoxesView(client.scene, "/pred", PRED_STYLE)
        self.gt_view = BoxesView(client.scene, "/gt", GT_STYLE)
        self.heatmap_view = HeatmapView(client.scene, "/heatmap")
        self.nav: NavigationPanel | None = None
        self.query: QueryPanel | None = None
        self.view: ViewPanel | None = None
        self.annotate_tab: viser.GuiTabHandle | None = None
        self.closed = False
        self._generation = 0
        self._frame_listeners: list[Listener] = []
        self._answer_listeners: list[Listener] = []

    # ------------------------------------------------------------------ public state

    @property
    def client_id(self) -> int:
        return self.client.client_id

    @property
    def sample(self) -> Sample | None:
        """The sample on screen."""
        return None if self.frame is None else self.frame.sample

    @property
    def predictions(self) -> Any | None:
        """The predictions drawn (``model.tpcnet.Predictions``), or None."""
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
        if self.closed:
            return
        try:
            self.client.add_notification(
                title,
                body,
                color=color,  # type: ignore[arg-type]
                auto_close_seconds=auto_close_seconds,
            )
        except Exception:  # The connection may be gone; the log keeps the message.
            log.warning("client %s: could not show notification %r", self.client_id, title)

    def report_error(self, title: str, error: BaseException | str) -> None:
        """Log an error and show it in this browser as a red notification."""
        if isinstance(error, BaseException):
            log.error("client %s: %s: %s", self.client_id, title, error, exc_info=error)
            body = f"{type(error).__name__}: {error}"
        else:
            log.error("client %s: %s: %s", self.client_id, title, error)
            body = error
        self.notify(title, body, color="red", auto_close_seconds=12.0)

    # ------------------------------------------------------------------ GUI

    def build_gui(self) -> None:
        """Create this browser's panel: note, Scene folder, Query / View / Annotate tabs."""
        gui = self.client.gui
        if self.app.model_note:
            gui.add_markdown(f"**Warning: {md_text(self.app.model_note)}**")
        with gui.add_folder("Scene"):
            self.nav = build_navigation_panel(gui, len(self.app.frames))
        tabs = gui.add_tab_group()
        sample_prompt = (self.sample.prompt or "") if self.sample is not None else ""
        with tabs.add_tab("Query", icon=viser.Icon.MESSAGE):
            self.query = build_query_panel(
                gui, self.app.engine.modalities, self.app.score_threshold, prompt=sample_prompt
            )
        with tabs.add_tab("View", icon=viser.Icon.EYE):
            self.view = build_view_panel(gui, self.scene_view.settings)
        self._wire_navigation(self.nav)
        self._wire_query(self.query)
        self._wire_view(self.view)
        if importlib.util.find_spec(ANNOTATION_MODULE) is not None:
            self.annotate_tab = tabs.add_tab("Annotate", icon=viser.Icon.PENCIL)
            with self.annotate_tab:
                try:
                    module = importlib.import_module(ANNOTATION_MODULE)
                    module.build_annotation_tab(self)
                except Exception as exc:
                    log.exception("the annotation panel failed to build")
                    gui.add_markdown(
                        f"The annotation panel failed: {md_text(f'{type(exc).__name__}: {exc}')}"
                    )

    def _wire_navigation(self, nav: NavigationPanel) -> None:
        @nav.step.on_click
        def _(event: viser.GuiEvent) -> None:
            self.app.step(-1 if event.target.value == PREVIOUS else 1, requester=self)

        @nav.frame_number.on_update
        def _(event: viser.GuiEvent) -> None:
            if event.client is None:  # Set by the server (a frame shown), not typed.
                return
            value = nav.frame_number.value
            if value is None:
                return
            self.app.go_to(int(round(value)) - 1, requester=self)

    def _wire_query(self, q: QueryPanel) -> None:
        @q.prompt.on_update
        def _(event: viser.GuiEvent) -> None:
            if event.client is None:
                return
            prompt = submitted_prompt(q.prompt.value)
            if prompt is None:
                return
            q.prompt.value = prompt  # Drop the line break (fires this callback without client).
            self.run_prompt(prompt)

        @q.run.on_click
        def _(_: viser.GuiEvent) -> None:
            self.run_prompt(q.prompt.value)

        @q.rerun.on_click
        def _(_: viser.GuiEvent) -> None:
            if q.history.value != NO_HISTORY:
                q.prompt.value = q.history.value
                self.run_prompt(q.history.value)

        @q.history.on_update
        def _(event: viser.GuiEvent) -> None:
            if event.client is not None and q.history.value != NO_HISTORY:
                q.prompt.value = q.history.value

        def rerun_last(event: viser.GuiEvent) -> None:
            if event.client is None:
                return
            if self.answer is not None:
                self.run_prompt(self.answer.prompt)
            elif self.sample is not None:
                self.app.engine.prefetch(self.sample, q.selected_modality())

        q.modality.on_update(rerun_last)
        q.threshold.on_update(rerun_last)

        @q.opacity.on_update
        def _(_: viser.GuiEvent) -> None:
            with self.lock:
                self.heatmap_view.set_opacity(q.opacity.value)

        @q.show_heatmap.on_update
        def _(_: viser.GuiEvent) -> None:
            with self.lock:
                self.heatmap_view.visible = q.show_heatmap.value

        @q.show_gt.on_update
        def _(_: viser.GuiEvent) -> None:
            with self.lock:
                self.gt_view.visible = q.show_gt.value

    def _wire_view(self, view: ViewPanel) -> None:
        def apply_settings(_: viser.GuiEvent) -> None:
            settings = view.settings()
            with self.lock, self.client.atomic():
                self.scene_view.apply(settings)
                view.update_legends(settings)

        for handle in view.inputs():
            handle.on_update(apply_settings)

        @view.camera.on_click
        def _(event: viser.GuiEvent) -> None:
            ground = self.frame.ground_z if self.frame is not None else self.scene_view.ground_z
            pose = bev_pose(ground) if event.target.value == "BEV" else chase_pose(ground)
            apply_pose(self.client.camera, pose)

    # ------------------------------------------------------------------ frames

    def show_frame(self, frame: Frame) -> None:
        """Draw ``frame`` (called by the app for every browser on navigation): points, ground
        truth, the sample's prompt in the prompt box; the previous answer is cleared."""
        with self.lock:
            if self.closed:
                return
            self._generation += 1
            self.frame = frame
            self.answer = None
            sample = frame.sample
            with self.client.atomic():
                self.scene_view.show(sample.lidar, sample.radar, frame.ground_z)
                self.pred_view.clear()
                self.heatmap_view.clear()
                self.gt_view.show(
                    sample.boxes, sample.classes, [box_label(c) for c in sample.classes]
                )
                if self.query is not None:
                    self.gt_view.visible = self.query.show_gt.value
                    self.query.prompt.value = sample.prompt or ""
                    self.query.results.content = "*Type a prompt and press Enter.*"
                if self.nav is not None:
                    self.nav.frame_number.value = frame.index + 1
                    self.nav.info.content = frame_markdown(frame, len(self.app.frames))
            self._call(self._frame_listeners)

    def update_frame_count(self) -> None:
        """Refresh the navigation widgets after the split changed size."""
        with self.lock:
            if self.nav is None:
                return
            count = len(self.app.frames)
            self.nav.frame_number.max = count
            self.nav.frame_number.hint = f"1..{count}"
            if self.app.frame is not None:
                self.frame = self.app.frame
                self.nav.frame_number.value = self.frame.index + 1
                self.nav.info.content = frame_markdown(self.frame, count)

    def reset_frame_number(self) -> None:
        """Put the frame number box back on the frame shown (after a failed jump)."""
        with self.lock:
            if self.nav is not None and self.frame is not None:
                self.nav.frame_number.value = self.frame.index + 1

    # ------------------------------------------------------------------ prompts

    def run_prompt(self, prompt: str | None) -> Future | None:
        """Answer ``prompt`` on the frame on screen, in the engine's worker pool.

        An empty prompt shows a notification instead. Returns the job's future (None when
        nothing was started).
        """
        received = time.perf_counter()
        text = normalise_prompt(prompt or "")
        if not text:
            self.notify(
                "Empty prompt",
                f'Type a sentence describing the objects to find, e.g. "{EXAMPLE_PROMPT}".',
                color="yellow",
            )
            return None
        with self.lock:
            if self.frame is None or self.query is None or self.closed:
                return None
            self._generation += 1
            request = QueryRequest(
                prompt=text,
                modality=self.query.selected_modality(),
                score_threshold=float(self.query.threshold.value),
                frame=self.frame,
                generation=self._generation,
                received=received,
            )
            self.query.results.content = f"*Running:* {md_text(text)}"
        return self.app.engine.submit(self._answer_job, request)

    def _stale(self, request: QueryRequest) -> bool:
        return self.closed or request.generation != self._generation

    def _answer_job(self, request: QueryRequest) -> None:
        if self._stale(request):
            return
        try:
            answer = self.app.engine.answer(
                request.frame.sample, request.modality, request.prompt, request.score_threshold
            )
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
        """Draw boxes, heatmap, summary and history (holding :attr:`lock`)."""
        assert self.query is not None
        pred = answer.predictions
        sample = request.frame.sample
        ious = best_iou(pred.boxes, sample.boxes)
        labels = [
            box_label(cls, float(score), float(iou))
            for cls, score, iou in zip(pred.classes, pred.scores, ious, strict=True)
        ]
        with self.client.atomic():
            self.pred_view.show(pred.boxes, pred.classes, labels)
            self.heatmap_view.visible = self.query.show_heatmap.value
            self.heatmap_view.show(
                pred.heatmaps, pred.grid, request.frame.ground_z, self.query.opacity.value
            )
        self.answer = answer
        self.history.add(request.prompt)
        self.query.history.options = self.history.options()
        self.query.history.value = self.history.items[0]
        self.query.rerun.disabled = False
        latency = (time.perf_counter() - request.received) * 1000.0
        self.last_latency_ms = latency
        self.query.results.content = results_markdown(answer, ious, latency)
        log.info(
            "client %s: %r on %s -> %d boxes in %.0f ms",
            self.client_id,
            request.prompt,
            answer.sample_id,
            len(pred.scores),
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
        """Forget this browser (it disconnected): pending answers are dropped."""
        with self.lock:
            self.closed = True
            self._generation += 1
