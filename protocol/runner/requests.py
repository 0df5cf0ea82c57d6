"""The experimenter's requests to a running session, from any thread: queued here, applied by the session runner.

:meth:`protocol.runner.session.SessionRunner.pause`, ``resume``, ``abort_trial``, ``abort_session``, ``note``,
``answer``, ``skip_questionnaire`` and ``answer_trial`` may be called from any thread (the GUI's engine, a headless
driver's signal handler); each only queues a :class:`Request`.  The runner takes the queue at the next block of
records it processes and applies each request at that block's first sample time, so a request has one moment on the
session clock and never races the trial machine.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

__all__ = ["REQUEST_KINDS", "Request", "Requests"]

#: What the experimenter may ask of a running session.
REQUEST_KINDS = ("pause", "resume", "abort_trial", "abort_session", "note", "answer", "skip_questionnaire",
                 "trial_answer")


@dataclass(frozen=True, slots=True)
class Request:
    """One request: its kind (:data:`REQUEST_KINDS`), its reason and abort cause (a note: its text), and the trial it
    names (None: the running one, whichever it is; a note: the session); ``deviation`` marks a note a deviation, and
    ``answers`` are a questionnaire's (``detail`` its name, ``cause`` its block; a skip's reason in ``answers`` as
    ``(("reason", text),)``)."""

    kind: str
    detail: str = ""
    cause: str = "experimenter"
    trial_index: int | None = None
    deviation: bool = False
    answers: tuple[tuple[str, float | str], ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in REQUEST_KINDS:
            raise ValueError(f"request {self.kind!r}: allowed are {', '.join(REQUEST_KINDS)}")


class Requests:
    """A thread-safe queue of :class:`Request` s: any thread puts, the runner's thread takes them all at once."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._queue: list[Request] = []

    def put(self, request: Request) -> None:
        """Queue a request (safe from any thread)."""
        with self._lock:
            self._queue.append(request)

    def take(self) -> list[Request]:
        """Every queued request, oldest first; the queue is empty again."""
        with self._lock:
            taken, self._queue = self._queue, []
        return taken
