"""The last stage before the motors: bound, slew-limit and ramp the rendered force.

A person's hand is on the device, so this stage guarantees, whatever comes in:

* the output is finite and its magnitude never exceeds ``min(f_max, device peak)``;
* it changes by at most ``slew_n_per_s · dt`` per tick (no kicks; science.md §5);
* when feedback is enabled the force fades in over ``ramp_in_s``;
* when feedback is disabled or a fault is active it fades to exactly zero
  within ``fault_ramp_s`` (≤ 50 ms), independent of the slew limit.

The output is ``gain · s`` where ``s`` is the slew-limited, clamped command and
``gain`` ∈ [0, 1] is the enable/fault ramp, so the fault ramp-down cannot be
slowed by the slew limit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from pipeline.core import exact
from pipeline.core.compiled import KernelState, State, fingerprint, kernel, warm_once
from pipeline.force.config import SafetyConfig
from pipeline.force.frames import Vec3

__all__ = ["GAIN", "STATE_SIZE", "SafetyConfig", "SafetyGovernor", "safety_step"]

# The governor's state, one float64 array: the ramp gain, the slew-limited command, the ramp and slew rates, the
# longest tick the rates count, the clamp radius a hair under the limit and its square.
_GAIN, _SX, _SY, _SZ, _UP, _DOWN, _SLEW, _MAX_DT, _LIM_INNER, _LIM2 = range(10)
#: The length of a governor's state array, and where in it the ramp gain is.
STATE_SIZE, GAIN = 10, _GAIN


def _compile(callees: int) -> Any:
    """:func:`safety_step` closed over the :func:`pipeline.core.compiled.fingerprint` of :mod:`pipeline.core.exact`
    (numba keys its cache on a kernel's own file and closure)."""

    @kernel
    def safety_step(st: State, fx: float, fy: float, fz: float, enabled: bool, dt_s: float) -> tuple[float, float,
                                                                                                     float]:
        """:meth:`SafetyGovernor.step` over the governor's state array ``st``."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        if not dt_s > 0.0:  # also catches NaN
            dt_s = 0.0
        max_dt = st[_MAX_DT]
        g = st[_GAIN]
        if enabled:
            g += st[_UP] * (dt_s if dt_s < max_dt else max_dt)
            if g > 1.0:
                g = 1.0
        else:
            # the ramp-down uses the true elapsed time: late ticks must not
            # stretch it beyond fault_ramp_s
            g -= st[_DOWN] * dt_s
            if g < 1e-12:  # snap: a geometric tail never reaches exactly 0
                g = 0.0
        st[_GAIN] = g
        if g == 0.0:
            # Output is off: restart the slew state from zero so re-enabling
            # ramps from rest instead of from a stale command.
            st[_SX] = 0.0
            st[_SY] = 0.0
            st[_SZ] = 0.0
            return (0.0, 0.0, 0.0)

        # Clamp to a hair under the limit: the slew step below is a convex
        # combination of two points in that ball, so with the 1e-12 margin no
        # rounding can carry the output past limit_n.
        if (fx - fx) + (fy - fy) + (fz - fz) != 0.0:
            fx = 0.0
            fy = 0.0
            fz = 0.0
        elif fx * fx + fy * fy + fz * fz > st[_LIM2]:  # inf when it overflows: also > lim²
            k = st[_LIM_INNER] / exact.hypot3(fx, fy, fz)
            fx, fy, fz = fx * k, fy * k, fz * k
        # slew-limit the command toward the (clamped) request
        sx, sy, sz = st[_SX], st[_SY], st[_SZ]
        dx, dy, dz = fx - sx, fy - sy, fz - sz
        step = st[_SLEW] * (dt_s if dt_s < max_dt else max_dt)
        if dx * dx + dy * dy + dz * dz > step * step:
            k = step / exact.hypot3(dx, dy, dz)
            dx, dy, dz = dx * k, dy * k, dz * k
        sx += dx
        sy += dy
        sz += dz
        st[_SX] = sx
        st[_SY] = sy
        st[_SZ] = sz
        return (sx * g, sy * g, sz * g)

    return safety_step


safety_step = _compile(fingerprint(exact))


class SafetyGovernor(KernelState):
    """Stateful safety stage; call :meth:`step` once per tick.

    Parameters
    ----------
    config
        The limits.
    device_peak_n
        The haptic device's peak force, N (the Touch's 3.3); the clamp is
        ``min(config.f_max_n, device_peak_n)``.

    The arithmetic of a tick is :func:`safety_step`'s, compiled, over the array :attr:`array` (Algorithm 1's compiled
    tick runs the same kernel on the framework's slice of it).
    """

    __slots__ = ("config", "device_limit_n", "limit_n", "static_limit_n")

    def __init__(self, config: SafetyConfig, device_peak_n: float) -> None:
        if not (isinstance(device_peak_n, (int, float)) and 1e-6 <= device_peak_n <= 1e3):
            raise ValueError(f"device_peak_n = {device_peak_n!r}: must be a number from 1e-06 to 1000 N")
        self.config = config
        #: The state (gain, command, rates, clamp) as :func:`safety_step` reads it.
        self.array: State = np.zeros(STATE_SIZE)
        #: ``min(f_max, device peak)``: the clamp when the device is not derating.
        self.static_limit_n = min(config.f_max_n, float(device_peak_n))
        #: The clamp now: :attr:`static_limit_n`, or the device's derated limit when that is lower.
        self.limit_n = self.static_limit_n
        #: The device's force limit as last given to :meth:`set_device_limit` (inf: none given), N.
        self.device_limit_n = math.inf
        self._set_clamp(self.limit_n)
        st = self.array
        st[_UP] = 1.0 / config.ramp_in_s
        st[_DOWN] = 1.0 / config.fault_ramp_s
        st[_SLEW] = config.slew_n_per_s
        st[_MAX_DT] = config.max_dt_s
        _warm(st)

    @property
    def gain(self) -> float:
        """Current ramp factor in [0, 1] (0 = output off)."""
        return float(self.array[_GAIN])

    def _set_clamp(self, limit_n: float) -> None:
        self.limit_n = limit_n
        inner = limit_n * (1.0 - 1e-12)
        self.array[_LIM_INNER] = inner
        self.array[_LIM2] = inner * inner

    def set_device_limit(self, device_limit_n: float) -> None:
        """The device's current force limit (its thermal derating), N: the clamp becomes the lower of it and the static
        one.

        A non-finite or non-positive limit leaves the static clamp (a device that does not say); the
        slew-limited state is clamped at once, so the next output is already within the new limit.
        """
        self.device_limit_n = float(device_limit_n)
        lim = self.static_limit_n
        if math.isfinite(device_limit_n) and 0.0 < device_limit_n < lim:
            lim = float(device_limit_n)
        self._set_clamp(lim)
        st = self.array
        sx, sy, sz = float(st[_SX]), float(st[_SY]), float(st[_SZ])
        if sx * sx + sy * sy + sz * sz > st[_LIM2]:
            k = float(st[_LIM_INNER]) / float(exact.hypot3(sx, sy, sz))
            st[_SX], st[_SY], st[_SZ] = sx * k, sy * k, sz * k

    def step(self, fx: float, fy: float, fz: float, enabled: bool, dt_s: float) -> Vec3:
        """Return the force to send to the device this tick.

        Parameters
        ----------
        fx, fy, fz
            Requested force, N (haptic frame).  Non-finite values request zero.
        enabled
            True when feedback is on and no fault is latched.
        dt_s
            Time since the previous tick, s (clipped to ``[0, max_dt_s]``).
        """
        return safety_step(self.array, float(fx), float(fy), float(fz), bool(enabled),  # type: ignore[no-any-return]
                           float(dt_s))  # (a kernel: converted, so that no call compiles another version)

    def force_zero(self) -> None:
        """Drop the output to zero at once (device reported an error: it is already off)."""
        st = self.array
        st[_GAIN] = st[_SX] = st[_SY] = st[_SZ] = 0.0

    def state(self) -> dict[str, float]:
        """The ramp gain and the slew-limited command, exact (see :meth:`load_state`)."""
        st = self.array
        return {"gain": float(st[_GAIN]), "sx": float(st[_SX]), "sy": float(st[_SY]), "sz": float(st[_SZ])}

    def load_state(self, d: Mapping[str, float]) -> None:
        """Continue exactly from a :meth:`state`."""
        st = self.array
        st[_GAIN] = float(d["gain"])
        st[_SX], st[_SY], st[_SZ] = float(d["sx"]), float(d["sy"]), float(d["sz"])


def _warm(array: State) -> None:
    """Compile :func:`safety_step` (or load it from numba's cache) once a process, on a copy of a governor's state: a
    governor's first step waits for no compiler."""
    warm_once(__name__, lambda: safety_step(array.copy(), 0.0, 0.0, 0.0, True, 0.001))
