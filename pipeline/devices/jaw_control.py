"""The instrument's jaw in the loop: the experimenter's controls and the Touch's stylus buttons drive the jaw actuator.

Paper §III-A: "two dedicated buttons, one for fully closing and another for
fully opening the jaws ... A short button press triggers incremental opening
or closing by detecting the signal's rising edge, while a long press
(exceeding 0.3 seconds) enables continuous actuation", with the firmware's
position limits.  The sketch does this for the Arduino's own buttons; here
the Touch's two stylus buttons do the same (:class:`StylusButtons`) -- unless
teleoperation claims them as deadman and clutch:

* a press steps once, on its rising edge (:data:`STEP_US`, 1 mm of rod travel);
* held beyond :data:`LONG_PRESS_S` it moves continuously at the actuator's
  no-load speed (:data:`CONT_STEP_US` every :data:`CONT_PERIOD_S`, 15 mm/s)
  until released or at the limit;
* both pressed at once: nothing (as the sketch).

The loop thread only feeds the buttons' state (:meth:`JawController.buttons`,
a compare and, on a change, a deque append); the serial I/O runs in
:meth:`JawController.service`, on the controller's own thread.  Every command
-- a control's, a short press's, a continuous move's start and end -- is a
:class:`JawEvent` for the study record and the experimenter's display.
"""

from __future__ import annotations

import collections
import threading
import time
from typing import Any, NamedTuple

__all__ = [
    "CONT_PERIOD_S",
    "CONT_STEP_US",
    "JAW_ACTIONS",
    "LONG_PRESS_S",
    "STEP_US",
    "JawController",
    "JawEvent",
    "StylusButtons",
]

#: One step of a short press or a step control, µs of pulse width (50 µs/mm: 1 mm of rod travel).
STEP_US = 50
#: A press held longer than this moves continuously, s.
LONG_PRESS_S = 0.3
#: Continuous motion: this many µs every period (15 µs / 20 ms = 15 mm/s, the PQ12's no-load speed).
CONT_STEP_US = 15
CONT_PERIOD_S = 0.020
#: What the controls ask for.
JAW_ACTIONS = ("open", "close", "step_open", "step_close")


class JawEvent(NamedTuple):
    """A jaw command carried out (or refused): ``t_ns`` on the controller's clock, its ``source`` and one line."""

    t_ns: int
    source: str
    detail: str
    pulse_us: int
    fraction_open: float
    at_limit: bool
    fault: str


class StylusButtons:
    """The short/long-press logic of the two stylus buttons (pure: times in, actions out).

    Parameters
    ----------
    close_button, open_button
        ``HD_CURRENT_BUTTONS`` bits of the button that closes and the one that opens.
    """

    def __init__(self, close_button: int = 1, open_button: int = 2) -> None:
        self.close_button, self.open_button = close_button, open_button
        self._mask = 0
        self._pressed_at: int | None = None
        self._which = ""  # "close" | "open": the button held alone
        self._moving = False

    def update(self, now_ns: int, mask: int) -> list[str]:
        """New button state: the actions to carry out (``step_close``, ``move_open``, ``stop``, ...)."""
        out: list[str] = []
        c, o = bool(mask & self.close_button), bool(mask & self.open_button)
        which = "close" if c and not o else "open" if o and not c else ""
        if mask != self._mask:
            self._mask = mask
            if self._moving and which != self._which:
                out.append("stop")
                self._moving = False
            if which and which != self._which:
                out.append(f"step_{which}")  # the rising edge: one step
                self._pressed_at = now_ns
            elif not which:
                self._pressed_at = None
            self._which = which
        if which and not self._moving and self._pressed_at is not None \
                and now_ns - self._pressed_at > LONG_PRESS_S * 1e9:
            self._moving = True
            out.append(f"move_{which}")
        return out


class JawController:
    """Carries out jaw commands off the loop thread and reports each one.

    Parameters
    ----------
    jaw
        The actuator (:class:`pipeline.backends.jaw.SerialJawActuator` or :class:`pipeline.sim.jaw.SimJaw`):
        ``open_jaw``, ``close_jaw``, ``step`` and ``status``.
    close_button, open_button
        Stylus buttons for the jaw; ``stylus=False``: the buttons are not the jaw's (teleoperation claims them).
    clock_ns
        Time source of :meth:`service` and the event times (wall clock: the actuator moves in real time).
    """

    def __init__(self, jaw: Any, *, close_button: int = 1, open_button: int = 2, stylus: bool = True,
                 clock_ns: Any = time.monotonic_ns) -> None:
        self.jaw = jaw
        self.stylus = StylusButtons(close_button, open_button) if stylus else None
        self.clock_ns = clock_ns
        self._todo: collections.deque[tuple[str, str]] = collections.deque()
        self.events: collections.deque[JawEvent] = collections.deque(maxlen=10_000)
        self._move: tuple[str, int, int] | None = None  # (direction, start ns, start µs)
        self._next_ns = 0
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None

    # -- any thread ------------------------------------------------------------------------------
    def submit(self, action: str, source: str = "experimenter") -> None:
        """Queue a control's command (one of :data:`JAW_ACTIONS`)."""
        if action not in JAW_ACTIONS:
            raise ValueError(f"jaw action = {action!r}: allowed values are {', '.join(JAW_ACTIONS)}")
        self._todo.append((action, source))
        self._wake.set()

    def buttons(self, now_ns: int, mask: int) -> None:
        """The stylus buttons' state (the loop thread, every tick): cheap unless something changed."""
        st = self.stylus
        if st is None or (mask == st._mask and not (mask and not st._moving)):
            return
        for action in st.update(now_ns, mask):
            self._todo.append((action, "stylus"))
            self._wake.set()

    # -- the controller's thread -----------------------------------------------------------------
    def service(self) -> None:
        """Carry out what is queued, and the continuous motion's steps that are due."""
        while self._todo:
            action, source = self._todo.popleft()
            self._do(action, source)
        mv = self._move
        if mv is not None and self.clock_ns() >= self._next_ns:
            self._next_ns += int(CONT_PERIOD_S * 1e9)
            self._step(CONT_STEP_US if mv[0] == "open" else -CONT_STEP_US)
            s = self.jaw.status
            if s.at_limit or s.fault or s.pos_us in (s.closed_us, s.open_us):
                self._end_move("at the limit" if not s.fault else "jaw fault")

    def _status(self) -> tuple[int, float, bool, str]:
        s = self.jaw.status
        return int(s.pos_us), float(s.fraction_open), bool(s.at_limit), str(s.fault)

    def _report(self, source: str, detail: str) -> None:
        pos, frac, lim, fault = self._status()
        self.events.append(JawEvent(self.clock_ns(), source, detail, pos, frac, lim, fault))

    def _call(self, fn: Any, *args: Any) -> str:
        try:
            fn(*args)
        except Exception as exc:  # JawFault / a lost port: reported, the jaw stays where it is
            return f"refused: {exc}"
        return ""

    def _step(self, delta: int) -> str:
        return self._call(self.jaw.step, delta)

    def _do(self, action: str, source: str) -> None:
        if action == "stop":
            self._end_move("released")
            return
        if action.startswith("move_"):
            direction = action[5:]
            self._move = (direction, self.clock_ns(), self._status()[0])
            self._next_ns = self.clock_ns()
            self._report(source, f"{direction} continuously (button held over {LONG_PRESS_S:g} s) from "
                                 f"{self._status()[0]} µs")
            return
        if self._move is not None:
            self._end_move("another command")
        if action == "open":
            err = self._call(self.jaw.open_jaw)
        elif action == "close":
            err = self._call(self.jaw.close_jaw)
        else:
            err = self._step(STEP_US if action == "step_open" else -STEP_US)
        pos, frac, lim, _ = self._status()
        words = {"open": "open fully", "close": "close fully", "step_open": f"step {STEP_US} µs toward open",
                 "step_close": f"step {STEP_US} µs toward closed"}[action]
        self._report(source, f"{words}: {err}" if err else
                     f"{words} → {pos} µs ({frac:.0%} open{', at the limit' if lim else ''})")

    def _end_move(self, why: str) -> None:
        mv, self._move = self._move, None
        if mv is None:
            return
        pos, frac, _, _ = self._status()
        secs = (self.clock_ns() - mv[1]) * 1e-9
        self._report("stylus",
                     f"{mv[0]} continuously: stopped ({why}) at {pos} µs ({frac:.0%} open) after {secs:.2f} s, "
                     f"{abs(pos - mv[2])} µs moved")

    # -- lifetime ----------------------------------------------------------------------------------
    def start(self) -> None:
        """Run :meth:`service` on a thread of its own (every 5 ms, and at once when something is queued)."""
        if self._thread is not None:
            return

        def run() -> None:
            while not self._stop.is_set():
                self._wake.wait(0.005)
                self._wake.clear()
                self.service()

        self._thread = threading.Thread(target=run, name="jaw-control", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the thread (the jaw stays where it is)."""
        self._stop.set()
        self._wake.set()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(1.0)
        self._thread = None
