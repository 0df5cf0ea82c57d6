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

from pipeline.force.frames import Vec3

__all__ = [
    "DEFAULT_COMMAND_TIMEOUT_S",
    "HD_ERRORS",
    "HD_EXCEEDED_MAX_FORCE",
    "HD_WARM_MOTORS",
    "HapticLimits",
    "MotorHeat",
    "TouchOutput",
    "hd_error_text",
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


class MotorHeat:
    """The Touch's thermal budget: heat, the derated force limit, and whether the budget was passed.

    :attr:`limit_n`, :attr:`fraction` and :attr:`over_budget` are kept up to date whenever the heat changes
    (they are read every servo and loop tick; the heat changes once per servo tick).

    Parameters
    ----------
    spec
        Peak, continuous rating, budget and where derating starts.
    """

    __slots__ = (
        "_budget",
        "_cont2",
        "_drop",
        "_from",
        "_h",
        "_peak",
        "_span",
        "fraction",
        "limit_n",
        "over_budget",
        "spec",
    )

    def __init__(self, spec: HapticLimits) -> None:
        self.spec = spec
        self._cont2 = spec.continuous_force_n ** 2
        self._budget = spec.thermal_budget_n2s
        self._from = spec.derate_from_fraction * spec.thermal_budget_n2s
        self._span = spec.thermal_budget_n2s - self._from
        self._peak = spec.peak_force_n
        self._drop = spec.peak_force_n - spec.continuous_force_n
        #: The force the device may render now, N: its peak, falling to the continuous rating as it warms.
        self.limit_n = self._peak
        #: Heat as a fraction of the budget (0 cold, 1 at the budget).
        self.fraction = 0.0
        #: The heat passed the budget (the device must stop: ``HD_WARM_MOTORS``).
        self.over_budget = False
        self._h = 0.0
        self.heat_n2s = 0.0

    @property
    def heat_n2s(self) -> float:
        """Motor heat above the continuous rating's steady state, N²·s (0 cold)."""
        return self._h

    @heat_n2s.setter
    def heat_n2s(self, h: float) -> None:
        self._h = h
        if h <= self._from:
            self.limit_n = self._peak
        elif h >= self._budget:
            self.limit_n = self.spec.continuous_force_n
        else:
            self.limit_n = self._peak - self._drop * (h - self._from) / self._span
        self.fraction = h / self._budget
        self.over_budget = h > self._budget

    def add(self, force_n: float, dt_s: float) -> None:
        """Account ``dt_s`` of rendering ``force_n`` (a magnitude, N)."""
        if dt_s > _MAX_HEAT_DT_S:
            dt_s = _MAX_HEAT_DT_S
        h = self._h + (force_n * force_n - self._cont2) * dt_s
        if h > 0.0:
            self.heat_n2s = h
        elif self._h != 0.0:  # cold, and it stays so: nothing to update (the common case at rest)
            self.heat_n2s = 0.0

    def cooled(self) -> bool:
        """Cool enough to re-arm after ``HD_WARM_MOTORS`` (half the budget)."""
        return self._h <= 0.5 * self._budget


class TouchOutput:
    """The latest command, with its time, and what the device renders from it (see the module docstring).

    :meth:`command` is called by whoever commands the device (the haptic loop's
    thread); :meth:`render` only in the device's own servo tick.  The command
    is one tuple replaced in a single assignment, so the servo thread never
    reads half of one.

    Parameters
    ----------
    spec
        Limits and thermal model.
    command_timeout_s
        A command this old renders as zero, s: a servo tick on the loop's 1 ms grid puts out zero at most
        this long after the last command, so at most this long after the loop stopped.
    """

    __slots__ = (
        "_cmd",
        "_timeout_ns",
        "command_timeout_s",
        "heat",
        "rendered_n",
        "spec",
        "stale",
        "stale_ticks",
        "warm",
    )

    def __init__(self, spec: HapticLimits, command_timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S) -> None:
        if isinstance(command_timeout_s, bool) or not (isinstance(command_timeout_s, (int, float))
                                                       and 0.0 < command_timeout_s <= 1.0):
            raise ValueError(f"command_timeout_s = {command_timeout_s!r}: must be a number of seconds above 0, "
                             "at most 1")
        self.spec = spec
        self.heat = MotorHeat(spec)
        self.command_timeout_s = float(command_timeout_s)
        self._timeout_ns = int(round(command_timeout_s * 1e9))
        self._cmd: tuple[float, float, float, int | None] = (0.0, 0.0, 0.0, None)
        #: What the last :meth:`render` put out, N (device frame).
        self.rendered_n: Vec3 = (0.0, 0.0, 0.0)
        #: The last render found the command stale (as old as the timeout) and put out zero.
        self.stale = False
        #: Renders that found the command stale (diagnostics).
        self.stale_ticks = 0
        #: The heat passed the budget: nothing is rendered until :meth:`rearm` succeeds.
        self.warm = False

    def command(self, fx: float, fy: float, fz: float, t_ns: int) -> None:
        """The force to render from now on (N, device frame), commanded at ``t_ns`` on the device's clock."""
        self._cmd = (fx, fy, fz, t_ns)

    @property
    def commanded(self) -> Vec3:
        """The latest command, N (whatever its age)."""
        c = self._cmd
        return (c[0], c[1], c[2])

    def clear(self) -> None:
        """Forget the command (a re-arm starts from zero, not from a stale command)."""
        self._cmd = (0.0, 0.0, 0.0, None)

    @property
    def limit_n(self) -> float:
        """The force the device may render now (its derated peak), N."""
        return self.heat.limit_n

    def render(self, now_ns: int, dt_s: float, enabled: bool = True) -> Vec3:
        """The force to put out this servo tick, and account its heat over ``dt_s``.

        Parameters
        ----------
        now_ns
            The device's clock now (the clock :meth:`command` times are on).
        dt_s
            Time since the previous render, s (the heat integration step).
        enabled
            False while the device is in an error state: output zero.
        """
        fx, fy, fz, t_cmd = self._cmd
        stale = t_cmd is None or now_ns - t_cmd >= self._timeout_ns
        self.stale = stale
        if stale or not enabled or self.warm:
            if stale:
                self.stale_ticks += 1
            fx = fy = fz = m = 0.0
        else:
            m = math.hypot(fx, fy, fz)
            if not math.isfinite(m):
                fx = fy = fz = m = 0.0
            else:
                lim = self.heat.limit_n
                if m > lim:
                    k = lim / m
                    fx, fy, fz, m = fx * k, fy * k, fz * k, lim
        heat = self.heat
        if dt_s > 0.0:
            heat.add(m, dt_s)
        if heat.over_budget and not self.warm:
            self.warm = True
            fx = fy = fz = 0.0
        out = (fx, fy, fz)
        self.rendered_n = out
        return out

    def rearm(self) -> bool:
        """Clear :attr:`warm` if the motors have cooled to half the budget; True if no longer warm."""
        if self.warm and not self.heat.cooled():
            return False
        self.warm = False
        self.clear()
        return True
