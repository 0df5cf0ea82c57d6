"""Simulated 3D Systems Touch: force output with the real device's limits (science.md §5).

The Touch's twin in the device registry (:mod:`pipeline.devices.registry`),
built with its model's limits.  What it renders is
:class:`pipeline.devices.touch_output.TouchOutput`'s, the one definition the
real backend uses too: a command as old as the command timeout (10 ms)
renders as zero, the output is clamped to the peak (the Touch's 3.3 N) and
derated as the motors warm (the thermal budget of the continuous rating,
0.88 N), and past the budget the device raises ``HD_WARM_MOTORS`` and renders
nothing until it has cooled to half the budget *and* the experimenter
re-arms it -- as OpenHaptics' ErrorHandling example prescribes.  Limits come
from a :class:`HapticLimits`, not constants; another impedance-type device
with the same output contract may use this twin with its own limits.

The rig steps it (:meth:`SimTouch.advance`) before the loop reads and
commands it in the same tick, so a command is one tick old when rendered; if
the loop stops commanding, the output is zero 10 ms later.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.core import exact
from pipeline.core.compiled import State, fingerprint, kernel, warm_once
from pipeline.core.record_writer import IntRow
from pipeline.devices import touch_output
from pipeline.devices.interfaces import HapticState
from pipeline.devices.registry import haptic_model
from pipeline.devices.touch_output import DEFAULT_COMMAND_TIMEOUT_S, HD_WARM_MOTORS, WARM, HapticLimits, TouchOutput
from pipeline.force.frames import Vec3

__all__ = [
    "SimTouch",
    "advance_kernel",
]

_new_tuple = tuple.__new__


def _compile_advance(callees: int) -> Any:
    """:func:`advance_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the module it calls."""

    @kernel
    def advance_kernel(st: State, sti: IntRow, now_ns: int, dt_s: float,
                       error_code: int) -> tuple[float, float, float, int]:
        """:meth:`SimTouch.advance` over its output's state: the force rendered for ``dt_s`` (while no error is
        raised) and the error code after it (``HD_WARM_MOTORS`` once the heat passed the budget)."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        fx, fy, fz = touch_output.render_kernel(st, sti, now_ns, dt_s, error_code == 0)
        if st[WARM] != 0.0 and error_code == 0:
            error_code = HD_WARM_MOTORS
        return fx, fy, fz, error_code

    return advance_kernel


#: The simulated Touch's step (:meth:`SimTouch.advance`), compiled.
advance_kernel = _compile_advance(fingerprint(exact, touch_output))


class SimTouch:
    """A ``HapticDevice`` whose stylus position is set by whoever holds it (the rig's hand model).

    Parameters
    ----------
    spec
        Limits and thermal model (None: the Touch model's).
    command_timeout_s
        A command this old (on the rig's clock) renders as zero.
    """

    def __init__(self, spec: HapticLimits | None = None, command_timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S) -> None:
        self.spec = spec or haptic_model("touch").limits
        self.output = TouchOutput(self.spec, command_timeout_s)
        warm_once(__name__, lambda: _compile_them(self.output))
        self.applied_force_n: Vec3 = (0.0, 0.0, 0.0)
        #: An HD error code (0 = none): ``HD_WARM_MOTORS`` from the heat model, or one a fault rehearsal sets.
        self.error_code = 0
        self.stylus_m: Vec3 = (0.0, 0.0, 0.0)
        self.buttons = 0
        self._t_ns = 0

    @property
    def peak_force_n(self) -> float:
        """Peak renderable force, N."""
        return self.spec.peak_force_n

    @property
    def command_timeout_s(self) -> float:
        """A command this old renders as zero (the device-side watchdog), s."""
        return self.output.command_timeout_s

    @property
    def continuous_force_n(self) -> float:
        """Continuous rating, N."""
        return self.spec.continuous_force_n

    @property
    def heat_n2s(self) -> float:
        """Motor heat, N²·s (:class:`pipeline.devices.touch_output.MotorHeat`)."""
        return self.output.heat.heat_n2s

    def command_force(self, fx: float, fy: float, fz: float, t_ns: int | None = None) -> None:
        """Latest force command, N, computed at ``t_ns`` (default: the rig's time now); rendered while fresh."""
        self.output.command(fx, fy, fz, self._t_ns if t_ns is None else t_ns)

    def advance(self, now_ns: int, dt_s: float) -> None:
        """Render the current command for ``dt_s``: watchdog, clamp, derate, heat, and fault when too warm."""
        self._t_ns = now_ns
        out = self.output
        fx, fy, fz, self.error_code = advance_kernel(out.array, out.ints, int(now_ns), float(dt_s),
                                                     int(self.error_code))
        self.applied_force_n = (fx, fy, fz)

    def ran_block(self, now_ns: int, stylus_m: Vec3, error_code: int) -> None:
        """Its steps ran in a compiled block of ticks (:mod:`pipeline.sim.block`) over its output's state, the last at
        ``now_ns``: take the stylus and the error code they left, and what the last rendered."""
        self._t_ns = now_ns
        self.stylus_m = stylus_m
        self.error_code = error_code
        self.applied_force_n = self.output.rendered_n

    def rearm(self) -> bool:
        """Clear a device error if the motors have cooled to half the budget."""
        if not self.output.rearm():
            return False
        self.error_code = 0
        return True

    def read_state(self) -> HapticState:
        """Stylus position (m, device frame), buttons, error code, the derated force limit and the heat fraction."""
        heat = self.output.heat
        # (tuple.__new__: the named tuple without its __new__'s Python frame, ~0.14 µs a tick)
        return _new_tuple(HapticState, (self._t_ns, self.stylus_m, self.buttons, self.error_code, heat.limit_n,
                                        heat.fraction))

    def close(self) -> None:
        """Zero the output."""
        self.output.clear()
        self.applied_force_n = (0.0, 0.0, 0.0)


def _compile_them(output: TouchOutput) -> None:
    """Compile :func:`advance_kernel` (or load it from numba's cache) on a copy of ``output``'s state: once a process,
    when the first simulated Touch is built, so that no tick waits for a compiler."""
    st = output.array.copy()
    advance_kernel(st, st.view(np.int64), 1, 0.001, 0)
