"""SIGINT and SIGTERM during training: finish the step, save, exit 130 / 143 with one line.

:class:`StopRequest` is a context manager that installs handlers for :data:`SIGNALS` (in the main
thread; elsewhere it installs nothing) and restores the previous ones on exit. Outside
:meth:`StopRequest.deferred` a signal raises :class:`TrainingInterrupted` at once: the run folder
is what it was, nothing is lost. Inside it (the training loop) a signal is only recorded; the loop
reads :attr:`StopRequest.signum` at each step boundary, writes the resumable state and raises
:class:`TrainingInterrupted` itself. Further signals while one is pending are ignored, so that
``torchrun`` forwarding the terminal's Ctrl-C to workers that received it already does not cut the
save short.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType, TracebackType

SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""The signals that stop a run cleanly."""


class TrainingInterrupted(BaseException):
    """Training stopped on a signal; :attr:`exit_code` is the shell's ``128 + signal``. A
    ``BaseException``, as ``KeyboardInterrupt``, so that no ``except Exception`` swallows it.

    Attributes:
        signum: The signal.
        detail: Where the run stopped and what was saved (one line), or empty.
    """

    def __init__(self, signum: int, detail: str = "") -> None:
        self.signum = int(signum)
        self.detail = detail
        super().__init__(self.message())

    @property
    def exit_code(self) -> int:
        """130 for SIGINT, 143 for SIGTERM."""
        return 128 + self.signum

    @property
    def name(self) -> str:
        """``"SIGINT"`` or ``"SIGTERM"``."""
        return signal.Signals(self.signum).name

    def message(self) -> str:
        """The one line the command prints."""
        return f"interrupted by {self.name}: {self.detail or 'nothing new to save'}"


class StopRequest:
    """Records the first of :data:`SIGNALS` (module docstring)."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self._deferring = False
        self._previous: dict[int, object] = {}

    def __enter__(self) -> StopRequest:
        if threading.current_thread() is threading.main_thread():
            for sig in SIGNALS:
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)  # type: ignore[arg-type]
        self._previous.clear()

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.signum is not None:
            return
        self.signum = signum
        if not self._deferring:
            raise TrainingInterrupted(signum)

    @contextlib.contextmanager
    def deferred(self) -> Iterator[None]:
        """Inside, a signal is recorded and left to the caller (the training loop)."""
        if self.signum is not None:
            raise TrainingInterrupted(self.signum)
        self._deferring = True
        try:
            yield
        finally:
            self._deferring = False


__all__ = ["SIGNALS", "StopRequest", "TrainingInterrupted"]
