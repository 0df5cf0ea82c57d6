"""Qt-free models of the experimenter GUI: behaviour lives here, windows only lay out and wire (napari style).

Each model holds plain data and :class:`Emitter` events that views connect to;
tests drive the models directly and assert the widgets.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["Emitter"]


class Emitter:
    """A tiny synchronous event: ``connect(fn)``, ``emit(*args)`` (observers never break the model)."""

    __slots__ = ("_slots",)

    def __init__(self) -> None:
        self._slots: list[Callable[..., Any]] = []

    def connect(self, fn: Callable[..., Any]) -> None:
        """Call ``fn`` on every :meth:`emit`."""
        self._slots.append(fn)

    def disconnect(self, fn: Callable[..., Any]) -> None:
        """Stop calling ``fn``."""
        self._slots.remove(fn)

    def emit(self, *args: Any) -> None:
        """Call every connected function; an exception in one is re-raised after all ran."""
        error: BaseException | None = None
        for fn in list(self._slots):
            try:
                fn(*args)
            except Exception as exc:  # one broken view must not starve the others
                error = error or exc
        if error is not None:
            raise error
