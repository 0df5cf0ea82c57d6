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
from dataclasses import dataclass

from pipeline.force.frames import Vec3

__all__ = ["SafetyConfig", "SafetyGovernor"]

_HYPOT = math.hypot


@dataclass(frozen=True, slots=True)
class SafetyConfig:
    """Limits of the safety stage.

    Attributes
    ----------
    f_max_n
        Largest rendered magnitude, N (the paper's f_max, 3 N).
    slew_n_per_s
        Largest rate of change of the rendered force, N/s (science.md §5: 20–50).
    ramp_in_s
        Time to fade feedback in after it is enabled or a fault is reset, s.
    fault_ramp_s
        Time to fade to zero on disable or fault, s; must be ≤ 0.05 (a fault
        must bring the force to zero within 50 ms).
    max_dt_s
        For the slew limit and the ramp-in, a tick longer than this (a stalled
        loop) counts as this long, so a late tick cannot jump the force up by
        more than one normal step.  The ramp-down uses the true time.
    """

    f_max_n: float = 3.0
    slew_n_per_s: float = 50.0
    ramp_in_s: float = 0.5
    fault_ramp_s: float = 0.04
    max_dt_s: float = 0.005

    def __post_init__(self) -> None:
        for name, lo, hi, unit in (
            ("f_max_n", 1e-6, 1e3, "N"),
            ("slew_n_per_s", 1e-3, 1e6, "N/s"),
            ("ramp_in_s", 1e-3, 60.0, "s"),
            ("fault_ramp_s", 1e-3, 0.05, "s"),
            ("max_dt_s", 1e-4, 1.0, "s"),
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo <= v <= hi):
                raise ValueError(f"safety.{name} = {v!r}: must be a number from {lo:g} to {hi:g} {unit}")


class SafetyGovernor:
    """Stateful safety stage; call :meth:`step` once per tick.

    Parameters
    ----------
    config
        The limits.
    device_peak_n
        The haptic device's peak force, N (the Touch's 3.3); the clamp is
        ``min(config.f_max_n, device_peak_n)``.
    """

    __slots__ = ("_down", "_lim2", "_lim_inner", "_max_dt", "_slew", "_sx", "_sy", "_sz", "_up", "config",
                 "device_limit_n", "gain", "limit_n", "static_limit_n")

    def __init__(self, config: SafetyConfig, device_peak_n: float) -> None:
        if not (isinstance(device_peak_n, (int, float)) and 1e-6 <= device_peak_n <= 1e3):
            raise ValueError(f"device_peak_n = {device_peak_n!r}: must be a number from 1e-06 to 1000 N")
        self.config = config
        #: ``min(f_max, device peak)``: the clamp when the device is not derating.
        self.static_limit_n = min(config.f_max_n, float(device_peak_n))
        #: The clamp now: :attr:`static_limit_n`, or the device's derated limit when that is lower.
        self.limit_n = self.static_limit_n
        #: The device's force limit as last given to :meth:`set_device_limit` (inf: none given), N.
        self.device_limit_n = math.inf
        self._set_clamp(self.limit_n)
        self._up = 1.0 / config.ramp_in_s
        self._down = 1.0 / config.fault_ramp_s
        self._slew = config.slew_n_per_s
        self._max_dt = config.max_dt_s
        self._sx = self._sy = self._sz = 0.0
        #: Current ramp factor in [0, 1] (0 = output off).
        self.gain = 0.0

    def _set_clamp(self, limit_n: float) -> None:
        self.limit_n = limit_n
        self._lim_inner = limit_n * (1.0 - 1e-12)
        self._lim2 = self._lim_inner * self._lim_inner

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
        sx, sy, sz = self._sx, self._sy, self._sz
        if sx * sx + sy * sy + sz * sz > self._lim2:
            k = self._lim_inner / _HYPOT(sx, sy, sz)
            self._sx, self._sy, self._sz = sx * k, sy * k, sz * k

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
        if not dt_s > 0.0:  # also catches NaN
            dt_s = 0.0
        g = self.gain
        if enabled:
            g += self._up * (dt_s if dt_s < self._max_dt else self._max_dt)
            if g > 1.0:
                g = 1.0
        else:
            # the ramp-down uses the true elapsed time: late ticks must not
            # stretch it beyond fault_ramp_s
            g -= self._down * dt_s
            if g < 1e-12:  # snap: a geometric tail never reaches exactly 0
                g = 0.0
        self.gain = g
        if g == 0.0:
            # Output is off: restart the slew state from zero so re-enabling
            # ramps from rest instead of from a stale command.
            self._sx = self._sy = self._sz = 0.0
            return (0.0, 0.0, 0.0)

        # Clamp to a hair under the limit: the slew step below is a convex
        # combination of two points in that ball, so with the 1e-12 margin no
        # rounding can carry the output past limit_n.
        lim = self._lim_inner
        if (fx - fx) + (fy - fy) + (fz - fz) != 0.0:
            fx = fy = fz = 0.0
        elif fx * fx + fy * fy + fz * fz > self._lim2:  # inf when it overflows: also > lim²
            k = lim / _HYPOT(fx, fy, fz)
            fx, fy, fz = fx * k, fy * k, fz * k
        # slew-limit the command toward the (clamped) request
        sx, sy, sz = self._sx, self._sy, self._sz
        dx, dy, dz = fx - sx, fy - sy, fz - sz
        step = self._slew * (dt_s if dt_s < self._max_dt else self._max_dt)
        if dx * dx + dy * dy + dz * dz > step * step:
            k = step / _HYPOT(dx, dy, dz)
            dx, dy, dz = dx * k, dy * k, dz * k
        sx += dx
        sy += dy
        sz += dz
        self._sx, self._sy, self._sz = sx, sy, sz
        return (sx * g, sy * g, sz * g)

    def force_zero(self) -> None:
        """Drop the output to zero at once (device reported an error: it is already off)."""
        self.gain = 0.0
        self._sx = self._sy = self._sz = 0.0

    def state(self) -> dict[str, float]:
        """The ramp gain and the slew-limited command, exact (see :meth:`load_state`)."""
        return {"gain": self.gain, "sx": self._sx, "sy": self._sy, "sz": self._sz}

    def load_state(self, d: Mapping[str, float]) -> None:
        """Continue exactly from a :meth:`state`."""
        self.gain = float(d["gain"])
        self._sx, self._sy, self._sz = float(d["sx"]), float(d["sy"]), float(d["sz"])
