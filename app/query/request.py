"""A prompt run through the engine: :class:`QueryRequest` (what one run asks) and
:func:`answer_request` (the model's answer to it, in an engine worker).

A request is made by :meth:`app.session.ClientSession.run_prompt` from a :class:`Prompt` the text
policy accepted (:mod:`app.query.prompt`) and the Query tab's settings at that moment
(:meth:`QueryRequest.of`); it carries the session's generation number, so that an answer arriving
after a newer prompt, a frame change or the browser leaving is dropped.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from app.engine import Answer, GroundingEngine, Modality
from app.query.panel import QueryPanel
from app.query.prompt import Prompt
from app.serving.navigation import Frame
from scenes.frame import Sample


@dataclass(frozen=True)
class QueryRequest:
    """One prompt to answer.

    Attributes:
        prompt: The prompt as :func:`app.query.prompt.read_prompt` accepted it (run as it is).
        modality: Sensors to use.
        score_threshold: Operating threshold: the referent-probability cut-off on the referent
            path, the decoder's score threshold on the paper's path.
        frame: The frame on screen when the prompt was sent.
        generation: The session's generation number at that moment.
        received: ``time.perf_counter()`` when the server received the prompt.
        labelled: Choose among the frame's labelled boxes instead of the detector's proposals.
    """

    prompt: Prompt
    modality: Modality
    score_threshold: float
    frame: Frame
    generation: int
    received: float
    labelled: bool = False

    def candidates(self, labelled_boxes: Callable[[Sample], object | None] | None) -> object:
        """What the referent stage chooses among: the frame's labelled boxes (from
        ``labelled_boxes``, :attr:`app.session.SessionOptions.labelled_boxes`) when the request
        asks for them, else None (the detector's proposals).

        Raises:
            ValueError: the request asks for labelled boxes the frame does not have.
        """
        if not self.labelled or labelled_boxes is None:
            return None
        boxes = labelled_boxes(self.frame.sample)
        if boxes is None:
            raise ValueError(
                f"frame {self.frame.sample.sample_id} has no labelled boxes: choose "
                "Candidates: Detector proposals"
            )
        return boxes

    @classmethod
    def of(
        cls, panel: QueryPanel, prompt: Prompt, frame: Frame, generation: int, received: float
    ) -> QueryRequest:
        """``prompt`` on ``frame`` with the Query tab's sensors, threshold and candidates."""
        return cls(
            prompt=prompt,
            modality=panel.selected_modality(),
            score_threshold=float(panel.threshold.value),
            labelled=panel.labelled_selected(),
            frame=frame,
            generation=generation,
            received=received,
        )


def answer_request(
    engine: GroundingEngine,
    request: QueryRequest,
    labelled_boxes: Callable[[Sample], object | None] | None,
) -> Answer:
    """The model's answer to ``request`` (blocking: run it in an engine worker,
    :meth:`GroundingEngine.submit`); ``labelled_boxes``: :attr:`SessionOptions.labelled_boxes
    <app.session_options.SessionOptions.labelled_boxes>`.

    Raises:
        ValueError: the request asks for labelled boxes the frame does not have; what the model
            raises.
    """
    return engine.answer(
        request.frame.sample,
        request.modality,
        request.prompt,
        request.score_threshold,
        request.candidates(labelled_boxes),
    )


__all__ = ["QueryRequest", "answer_request"]
