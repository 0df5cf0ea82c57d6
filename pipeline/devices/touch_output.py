"""What a 3D Systems Touch renders from the force it was last commanded: one definition for both devices.

The simulated Touch (:class:`pipeline.sim.touch.SimTouch`, once per rig step)
and the real one (:class:`pipeline.backends.touch.TouchHapticDevice`, once per
OpenHaptics servo tick, in the device's own scheduler thread) both render
through :meth:`TouchOutput.render`, which applies, in this order:

1. **Command watchdog.**  A command is rendered only while it is fresh: once
   it is ``command_timeout_s`` old (10 ms by default) the output is
   exactly zero, whatever the process that commands the device is doing --
   its loop thread may have died, frozen, or its final zero command may have
   been skipped.  OpenHaptics has no such watchdog of its own (the device
   renders the last ``hdSetDoublev`` for as long as the scheduler runs); the
   dVRK's IO watchdog does the same at 30 ms (science.md §5).  10 ms is ten
   missed loop ticks, inside the 50 ms in which every fault must reach zero.
2. **Non-finite → zero; clamp to the derated peak.**  The peak is the
   device's (:class:`HapticLimits`: the Touch's 3.3 N, from its model in
   :mod:`pipeline.devices.registry`); the motor-heat model below lowers it
   when the motors get warm.
3. **Motor heat** (:class:`MotorHeat`): the thermal budget of the continuous
   rating, and ``HD_WARM_MOTORS`` as a backstop.

Heat model (science.md §5: "track an I²t or time-above-continuous budget")::

    heat += (|f|² − f_cont²)·dt,   never below 0           (N²·s)

``f_cont`` is the continuous rating (the Touch's 0.88 N); the budget is
``HapticLimits.thermal_budget_n2s``.  Above ``derate_from_fraction`` of the budget
the device **derates**: its force limit falls linearly from the peak to the
continuous rating as the heat approaches the budget -- the OpenHaptics
examples' "clamp toward the continuous value when the motors warm up".  At the
continuous rating the heat stops growing, so a derating device reaches the
budget only asymptotically; should it pass the budget anyway (a long servo
stall followed by a full-force tick), the device raises ``HD_WARM_MOTORS`` and
renders nothing until it has cooled to half the budget and is re-armed, as
OpenHaptics' ErrorHandling example prescribes.

The paper's study forces stay below the continuous rating (a 1.2 N tissue
force renders 0.51 N), so heat only accumulates when a participant presses
the tissue above ~2.1 N (science.md §0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from pipeline.core import exact
from pipeline.core.compiled import State, fingerprint, kernel, warm_once
from pipeline.core.record_writer import IntRow
from pipeline.force.frames import Vec3

__all__ = [
    "DEFAULT_COMMAND_TIMEOUT_S",
    "HD_ERRORS",
    "HD_EXCEEDED_MAX_FORCE",
    "HD_WARM_MOTORS",
    "STATE_SIZE",
    "WARM",
    "HapticLimits",
    "MotorHeat",
    "TouchOutput",
    "command_kernel",
    "hd_error_text",
    "render_kernel",
]

#: OpenHaptics ``HD_WARM_MOTORS`` (hdDefines.h).
HD_WARM_MOTORS = 0x0200
#: OpenHaptics ``HD_EXCEEDED_MAX_FORCE``.
HD_EXCEEDED_MAX_FORCE = 0x0201
#: OpenHaptics' HD error codes (hdDefines.h) by name, with what each means at the bench: a fault's line names the
#: code, not only its number.
HD_ERRORS: dict[int, tuple[str, str]] = {
    0x0100: ("HD_INVALID_ENUM", "the driver was called with an unknown parameter"),
    0x0101: ("HD_INVALID_VALUE", "the driver was given a value out of range"),
    0x0102: ("HD_INVALID_OPERATION", "the driver refused the operation in its current state"),
    0x0104: ("HD_BAD_HANDLE", "the device handle is no longer valid (the device was closed or unplugged)"),
    HD_WARM_MOTORS: ("HD_WARM_MOTORS", "the motors are too warm: the device limits its force until they cool"),
    HD_EXCEEDED_MAX_FORCE: ("HD_EXCEEDED_MAX_FORCE", "a force above the device's maximum was commanded"),
    0x0202: ("HD_EXCEEDED_MAX_FORCE_IMPULSE", "the force changed faster than the device allows"),
    0x0203: ("HD_EXCEEDED_MAX_VELOCITY", "the stylus moved faster than the device allows"),
    0x0204: ("HD_FORCE_ERROR", "the device could not render the commanded force"),
    0x0300: ("HD_DEVICE_FAULT", "the device reports a hardware fault (check its cable and power, then reset)"),
    0x0301: ("HD_DEVICE_ALREADY_INITIATED", "the device is already opened by another program"),
    0x0302: ("HD_COMM_ERROR", "communication with the device failed (its cable, or its USB/Ethernet link)"),
    0x0303: ("HD_COMM_CONFIG_ERROR", "the device's communication is not configured (Touch Setup)"),
    0x0304: ("HD_TIMER_ERROR", "the servo loop's timer failed"),
    0x0400: ("HD_ILLEGAL_BEGIN", "a haptic frame was begun inside another"),
    0x0401: ("HD_ILLEGAL_END", "a haptic frame was ended without a begin"),
    0x0402: ("HD_FRAME_ERROR", "a haptic frame failed"),
    0x0500: ("HD_INVALID_PRIORITY", "the scheduler was given an invalid priority"),
    0x0501: ("HD_SCHEDULER_FULL", "the servo scheduler has no room for another callback"),
    0x0600: ("HD_INVALID_LICENSE", "the OpenHaptics licence is not valid"),
}


def hd_error_text(code: int) -> str:
    """``0x0300 (HD_DEVICE_FAULT: the device reports a hardware fault …)``; an unknown code as its number alone."""
    name = HD_ERRORS.get(int(code))
    return f"0x{int(code):04X}" + (f" ({name[0]}: {name[1]})" if name is not None else " (not an OpenHaptics code "
                                                                                         "this software knows)")


#: A command this old renders as zero (device-side watchdog), s.
DEFAULT_COMMAND_TIMEOUT_S = 0.010
#: Longest servo interval the heat model integrates in one step, s (a stalled servo thread is not an eternity).
_MAX_HEAT_DT_S = 0.1


@dataclass(frozen=True, slots=True)
class HapticLimits:
    """What a haptic device can render: its force limits and its motors' thermal model.

    A device model's limits (:class:`pipeline.devices.registry.HapticModel`, where each value's source is
    given); the real backend takes the peak and continuous rating the device itself reports.

    Attributes
    ----------
    peak_force_n
        The largest force the device renders, N (OpenHaptics' ``HD_NOMINAL_MAX_FORCE``).
    continuous_force_n
        The force its motors sustain without warming, N (``HD_NOMINAL_MAX_CONTINUOUS_FORCE``).
    thermal_budget_n2s
        Heat the motors take above the continuous rating, N²·s.
    derate_from_fraction
        Derating starts at this fraction of the budget.
    """

    peak_force_n: float
    continuous_force_n: float
    thermal_budget_n2s: float
    derate_from_fraction: float = 0.5

    def __post_init__(self) -> None:
        for name in ("peak_force_n", "continuous_force_n", "thermal_budget_n2s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"haptic.{name} = {v!r}: must be a finite number > 0")
        if self.continuous_force_n > self.peak_force_n:
            raise ValueError(f"haptic.continuous_force_n = {self.continuous_force_n!r}: must be at most "
                             f"peak_force_n ({self.peak_force_n!r})")
        f = self.derate_from_fraction
        if not (math.isfinite(f) and 0.0 <= f < 1.0):
            raise ValueError(f"haptic.derate_from_fraction = {f!r}: must be a number from 0 to below 1")



# The output's state, one float64 array (its kernels' layout; the times are int64 in the same memory, the array's int64
# view): the command (N, device frame), its time on the device's clock and whether there is one, what the last render
# put out, whether it found the command stale, how many did, whether the budget was passed (HD_WARM_MOTORS); the
# heat (MotorHeat): the heat, the derated limit, the fraction of the budget, over the budget; then the constants.
_CMD, _CMD_T, _HAS_CMD, _RENDERED, _STALE, _STALE_TICKS, _WARM = 0, 3, 4, 5, 8, 9, 10
_HEAT, _LIMIT, _FRACTION, _OVER = 11, 12, 13, 14
_TIMEOUT_NS, _CONT2, _BUDGET, _FROM, _SPAN, _PEAK, _DROP, _CONT = 15, 16, 17, 18, 19, 20, 21, 22
STATE_SIZE = 23
#: Where the state says the budget was passed (HD_WARM_MOTORS): the simulated Touch raises its error from it.
WARM = _WARM
#: Where the state holds the derated force limit (N) and what the last render put out.
LIMIT_AT, RENDERED_AT = _LIMIT, _RENDERED


@kernel
def set_heat_kernel(st: State, h: float) -> None:
    """The heat is ``h`` (N²·s): the derated limit, the fraction of the budget and whether it is passed with it."""
    st[_HEAT] = h
    if h <= st[_FROM]:
        st[_LIMIT] = st[_PEAK]
    elif h >= st[_BUDGET]:
        st[_LIMIT] = st[_CONT]
    else:
        st[_LIMIT] = st[_PEAK] - st[_DROP] * (h - st[_FROM]) / st[_SPAN]
    st[_FRACTION] = h / st[_BUDGET]
    st[_OVER] = 1.0 if h > st[_BUDGET] else 0.0


@kernel
def add_heat_kernel(st: State, force_n: float, dt_s: float) -> None:
    """Account ``dt_s`` of rendering ``force_n`` (a magnitude, N): :meth:`MotorHeat.add`."""
    if dt_s > _MAX_HEAT_DT_S:
        dt_s = _MAX_HEAT_DT_S
    h = st[_HEAT] + (force_n * force_n - st[_CONT2]) * dt_s
    if h > 0.0:
        set_heat_kernel(st, h)
    elif st[_HEAT] != 0.0:  # cold, and it stays so: nothing to update (the common case at rest)
        set_heat_kernel(st, 0.0)


@kernel
def command_kernel(st: State, sti: IntRow, fx: float, fy: float, fz: float, t_ns: int) -> None:
    """The force to render from now on (N, device frame), commanded at ``t_ns``: :meth:`TouchOutput.command`.

    One compiled call: a servo thread (the real Touch's) never renders half of a command (a compiled call holds the
    interpreter's lock throughout)."""
    st[_CMD] = fx
    st[_CMD + 1] = fy
    st[_CMD + 2] = fz
    sti[_CMD_T] = t_ns
    st[_HAS_CMD] = 1.0


@kernel
def clear_kernel(st: State, sti: IntRow, rearm: bool) -> None:
    """Forget the command (and with ``rearm`` the passed budget's stop) in one call: :meth:`TouchOutput.clear`,
    :meth:`TouchOutput.rearm`."""
    st[_CMD] = 0.0
    st[_CMD + 1] = 0.0
    st[_CMD + 2] = 0.0
    sti[_CMD_T] = 0
    st[_HAS_CMD] = 0.0
    if rearm:
        st[_WARM] = 0.0


def _compile_render(callees: int) -> Any:
    """:func:`render_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the module it calls."""

    @kernel
    def render_kernel(st: State, sti: IntRow, now_ns: int, dt_s: float, enabled: bool) -> tuple[float, float, float]:
        """The force to put out this servo tick, its heat accounted over ``dt_s``: :meth:`TouchOutput.render`."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        fx, fy, fz = st[_CMD], st[_CMD + 1], st[_CMD + 2]
        stale = st[_HAS_CMD] == 0.0 or now_ns - sti[_CMD_T] >= sti[_TIMEOUT_NS]
        st[_STALE] = 1.0 if stale else 0.0
        if stale or not enabled or st[_WARM] != 0.0:
            if stale:
                st[_STALE_TICKS] += 1.0
            fx = fy = fz = m = 0.0
        else:
            m = exact.hypot3(fx, fy, fz)  # (math.hypot's bits: pipeline.core.exact)
            if m - m != 0.0:  # (not finite: inf - inf and NaN - NaN are NaN)
                fx = fy = fz = m = 0.0
            else:
                lim = st[_LIMIT]
                if m > lim:
                    k = lim / m
                    fx, fy, fz, m = fx * k, fy * k, fz * k, lim
        if dt_s > 0.0:
            add_heat_kernel(st, m, dt_s)
        if st[_OVER] != 0.0 and st[_WARM] == 0.0:
            st[_WARM] = 1.0
            fx = fy = fz = 0.0
        st[_RENDERED] = fx
        st[_RENDERED + 1] = fy
        st[_RENDERED + 2] = fz
        return fx, fy, fz

    return render_kernel


#: What the device renders this servo tick (:meth:`TouchOutput.render`), compiled.
render_kernel = _compile_render(fingerprint(exact))


class MotorHeat:
    """The Touch's thermal budget: heat, the derated force limit, and whether the budget was passed.

    :attr:`limit_n`, :attr:`fraction` and :attr:`over_budget` are kept up to date whenever the heat changes
    (:func:`set_heat_kernel`; they are read every servo and loop tick, the heat changes once per servo tick).  The
    state is its :class:`TouchOutput`'s array (or its own).

    Parameters
    ----------
    spec
        Peak, continuous rating, budget and where derating starts.
    array
        The state to keep it in (a :class:`TouchOutput`'s); None: its own.
    """

    __slots__ = ("array", "spec")

    def __init__(self, spec: HapticLimits, array: State | None = None) -> None:
        warm_once(__name__, _compile_them)
        self.spec = spec
        self.array = st = array if array is not None else np.zeros(STATE_SIZE)
        st[_CONT2] = spec.continuous_force_n ** 2
        st[_BUDGET] = spec.thermal_budget_n2s
        st[_FROM] = spec.derate_from_fraction * spec.thermal_budget_n2s
        st[_SPAN] = spec.thermal_budget_n2s - st[_FROM]
        st[_PEAK], st[_CONT] = spec.peak_force_n, spec.continuous_force_n
        st[_DROP] = spec.peak_force_n - spec.continuous_force_n
        set_heat_kernel(st, 0.0)

    @property
    def limit_n(self) -> float:
        """The force the device may render now, N: its peak, falling to the continuous rating as it warms."""
        return float(self.array[_LIMIT])

    @property
    def fraction(self) -> float:
        """Heat as a fraction of the budget (0 cold, 1 at the budget)."""
        return float(self.array[_FRACTION])

    @property
    def over_budget(self) -> bool:
        """The heat passed the budget (the device must stop: ``HD_WARM_MOTORS``)."""
        return bool(self.array[_OVER])

    @property
    def heat_n2s(self) -> float:
        """Motor heat above the continuous rating's steady state, N²·s (0 cold)."""
        return float(self.array[_HEAT])

    @heat_n2s.setter
    def heat_n2s(self, h: float) -> None:
        set_heat_kernel(self.array, float(h))

    def add(self, force_n: float, dt_s: float) -> None:
        """Account ``dt_s`` of rendering ``force_n`` (a magnitude, N)."""
        add_heat_kernel(self.array, float(force_n), float(dt_s))

    def cooled(self) -> bool:
        """Cool enough to re-arm after ``HD_WARM_MOTORS`` (half the budget)."""
        return self.heat_n2s <= 0.5 * self.spec.thermal_budget_n2s


class TouchOutput:
    """The latest command, with its time, and what the device renders from it (see the module docstring).

    :meth:`command` is called by whoever commands the device (the haptic loop's thread); :meth:`render` only in the
    device's own servo tick.  Each is one compiled call over the output's state (:attr:`array`:
    :func:`command_kernel`, :func:`render_kernel`), which holds the interpreter's lock throughout, so the servo thread
    never reads half of a command.

    Parameters
    ----------
    spec
        Limits and thermal model.
    command_timeout_s
        A command this old renders as zero, s: a servo tick on the loop's 1 ms grid puts out zero at most
        this long after the last command, so at most this long after the loop stopped.
    """

    __slots__ = ("array", "command_timeout_s", "heat", "ints", "spec")

    def __init__(self, spec: HapticLimits, command_timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S) -> None:
        if isinstance(command_timeout_s, bool) or not (isinstance(command_timeout_s, (int, float))
                                                       and 0.0 < command_timeout_s <= 1.0):
            raise ValueError(f"command_timeout_s = {command_timeout_s!r}: must be a number of seconds above 0, "
                             "at most 1")
        self.spec = spec
        #: The state (the module's layout) and its int64 view (the times).
        self.array: State = np.zeros(STATE_SIZE)
        self.ints: IntRow = self.array.view(np.int64)
        self.heat = MotorHeat(spec, self.array)
        self.command_timeout_s = float(command_timeout_s)
        self.ints[_TIMEOUT_NS] = int(round(command_timeout_s * 1e9))

    def command(self, fx: float, fy: float, fz: float, t_ns: int) -> None:
        """The force to render from now on (N, device frame), commanded at ``t_ns`` on the device's clock."""
        command_kernel(self.array, self.ints, float(fx), float(fy), float(fz), int(t_ns))

    @property
    def commanded(self) -> Vec3:
        """The latest command, N (whatever its age)."""
        c = self.array[_CMD:_CMD + 3].tolist()
        return (c[0], c[1], c[2])

    @property
    def rendered_n(self) -> Vec3:
        """What the last :meth:`render` put out, N (device frame)."""
        r = self.array[_RENDERED:_RENDERED + 3].tolist()
        return (r[0], r[1], r[2])

    @property
    def stale(self) -> bool:
        """The last render found the command stale (as old as the timeout) and put out zero."""
        return bool(self.array[_STALE])

    @property
    def stale_ticks(self) -> int:
        """Renders that found the command stale (diagnostics)."""
        return int(self.array[_STALE_TICKS])

    @property
    def warm(self) -> bool:
        """The heat passed the budget: nothing is rendered until :meth:`rearm` succeeds."""
        return bool(self.array[_WARM])

    def clear(self) -> None:
        """Forget the command (a re-arm starts from zero, not from a stale command)."""
        clear_kernel(self.array, self.ints, False)

    @property
    def limit_n(self) -> float:
        """The force the device may render now (its derated peak), N."""
        return self.heat.limit_n

    def render(self, now_ns: int, dt_s: float, enabled: bool = True) -> Vec3:
        """The force to put out this servo tick, and account its heat over ``dt_s`` (:func:`render_kernel`).

        Parameters
        ----------
        now_ns
            The device's clock now (the clock :meth:`command` times are on).
        dt_s
            Time since the previous render, s (the heat integration step).
        enabled
            False while the device is in an error state: output zero.
        """
        return cast(Vec3, render_kernel(self.array, self.ints, int(now_ns), float(dt_s), bool(enabled)))

    def rearm(self) -> bool:
        """Clear :attr:`warm` if the motors have cooled to half the budget; True if no longer warm."""
        if self.warm and not self.heat.cooled():
            return False
        clear_kernel(self.array, self.ints, True)  # (one call: no servo tick renders the old command in between)
        return True

    def __getstate__(self) -> dict[str, Any]:
        return {"spec": self.spec, "array": self.array, "command_timeout_s": self.command_timeout_s}

    def __setstate__(self, state: dict[str, Any]) -> None:
        """A copy (``copy.deepcopy``, pickle) keeps its times in an int64 view of its own state, and its heat model
        that state, as the original does."""
        self.spec, self.array, self.command_timeout_s = state["spec"], state["array"], state["command_timeout_s"]
        self.ints = self.array.view(np.int64)
        self.heat = MotorHeat.__new__(MotorHeat)
        self.heat.spec, self.heat.array = self.spec, self.array


def _compile_them() -> None:
    """Compile the output's kernels (or load them from numba's cache) on a scratch state, as its methods call them:
    once a process, at the first output's or heat model's construction, so that no servo or loop tick waits for a
    compiler."""
    st = np.zeros(STATE_SIZE)
    st[_BUDGET] = st[_SPAN] = st[_PEAK] = st[_CONT] = 1.0
    si = st.view(np.int64)
    set_heat_kernel(st, 0.0)
    command_kernel(st, si, 0.0, 0.0, 0.0, 0)
    clear_kernel(st, si, False)
    render_kernel(st, si, 1, 0.001, True)
    add_heat_kernel(st, 0.0, 0.001)
