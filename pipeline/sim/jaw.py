"""Simulated jaw actuator: the Arduino sketch's position logic (``firmware/jaw_actuator``) without a serial port.

Same interface as :class:`pipeline.backends.jaw.SerialJawActuator` -- ``open_jaw``,
``close_jaw``, ``step``, ``set_pulse_us``, ``status`` -- and the sketch's limits:
pulse widths clipped to 1100 µs (closed) .. 1900 µs (open), a step in µs toward
open (negative: toward closed).  ``fault`` (a string) makes every command fail
like an unplugged port until :meth:`SimJaw.reconnect`.
"""

from __future__ import annotations

import math

from pipeline.backends.jaw import JawFault, JawStatus

__all__ = ["SimJaw"]

CLOSED_US, OPEN_US, START_US = 1100, 1900, 1100


class SimJaw:
    """A :class:`pipeline.devices.interfaces.JawActuator` with the firmware's limits."""

    def __init__(self) -> None:
        self.status = JawStatus()
        s = self.status
        s.closed_us, s.open_us, s.pos_us = CLOSED_US, OPEN_US, START_US
        self.commands: list[str] = []  # what was sent, as the sketch's command lines

    def _move(self, line: str, target: int) -> int:
        s = self.status
        if s.fault:
            raise JawFault(f"jaw actuator is in fault: {s.fault}; reconnect it")
        self.commands.append(line)
        lo, hi = min(s.closed_us, s.open_us), max(s.closed_us, s.open_us)
        s.pos_us = min(hi, max(lo, target))
        s.at_limit = s.pos_us != target  # the sketch answers LIMIT when it clipped the target
        return s.pos_us

    def open_jaw(self) -> int:
        """Open fully; the pulse width, µs."""
        return self._move("OPEN", self.status.open_us)

    def close_jaw(self) -> int:
        """Close fully; the pulse width, µs."""
        return self._move("CLOSE", self.status.closed_us)

    def step(self, delta_us: int) -> int:
        """Move ``delta_us`` toward open (negative: toward closed), clipped at the limits."""
        if isinstance(delta_us, bool) or not isinstance(delta_us, int) or not -1000 <= delta_us <= 1000:
            raise ValueError(f"delta_us = {delta_us!r}: must be a whole number of µs from -1000 to 1000")
        s = self.status
        direction = 1 if s.open_us > s.closed_us else -1
        return self._move(f"STEP {delta_us}", s.pos_us + direction * delta_us)

    def set_pulse_us(self, pulse_us: int) -> int:
        """Command a pulse width, µs (clipped to the limits)."""
        return self._move(f"SET {pulse_us}", int(pulse_us))

    def set_position(self, fraction_open: float) -> None:
        """Move to a fraction of the stroke (0 closed, 1 open)."""
        if not isinstance(fraction_open, (int, float)) or not math.isfinite(fraction_open):
            raise ValueError(f"fraction_open = {fraction_open!r}: must be a finite number from 0 to 1")
        s = self.status
        self.set_pulse_us(round(s.closed_us + min(1.0, max(0.0, float(fraction_open))) * (s.open_us - s.closed_us)))

    def reconnect(self) -> None:
        """Clear a fault (the experimenter re-plugged it)."""
        self.status.fault = ""

    def close(self) -> None:
        """Nothing to release (the jaw stays where it is)."""
