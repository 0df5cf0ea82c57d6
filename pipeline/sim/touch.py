"""Simulated 3D Systems Touch: force output with the real device's limits (science.md §5).

The device clamps to its peak force (3.3 N) like ``HD_MAX_FORCE_CLAMPING`` and
keeps a thermal budget for its continuous rating (0.88 N): heat accumulates as
``∫ (|f|² − f_cont²) dt`` (never below zero) and, past the budget, the device
raises ``HD_WARM_MOTORS`` and renders nothing until it has cooled to half the
budget *and* the experimenter re-arms it -- as OpenHaptics' ErrorHandling
example prescribes.  Limits come from a :class:`TouchSpec`, not constants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pipeline.devices import HapticState
from pipeline.frames import Vec3

__all__ = ["HD_EXCEEDED_MAX_FORCE", "HD_WARM_MOTORS", "SimTouch", "TouchSpec"]

HD_WARM_MOTORS = 0x0200
HD_EXCEEDED_MAX_FORCE = 0x0201


@dataclass(frozen=True, slots=True)
class TouchSpec:
    """Device limits (3D Systems Touch defaults)."""

    peak_force_n: float = 3.3
    continuous_force_n: float = 0.88
    thermal_budget_n2s: float = 60.0

    def __post_init__(self) -> None:
        for name in ("peak_force_n", "continuous_force_n", "thermal_budget_n2s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"touch.{name} = {v!r}: must be a finite number > 0")


class SimTouch:
    """A ``HapticDevice`` whose stylus position is set by whoever holds it (the rig's hand model)."""

    def __init__(self, spec: TouchSpec | None = None) -> None:
        self.spec = spec or TouchSpec()
        self._cmd: Vec3 = (0.0, 0.0, 0.0)
        self.applied_force_n: Vec3 = (0.0, 0.0, 0.0)
        self.heat_n2s = 0.0
        self.error_code = 0
        self.stylus_m: Vec3 = (0.0, 0.0, 0.0)
        self.buttons = 0
        self._t_ns = 0

    @property
    def peak_force_n(self) -> float:
        """Peak renderable force, N."""
        return self.spec.peak_force_n

    @property
    def continuous_force_n(self) -> float:
        """Continuous rating, N."""
        return self.spec.continuous_force_n

    def command_force(self, fx: float, fy: float, fz: float) -> None:
        """Latest force command, N (the servo loop renders it until the next)."""
        self._cmd = (fx, fy, fz)

    def advance(self, now_ns: int, dt_s: float) -> None:
        """Render the current command for ``dt_s``: clamp, heat, and fault when too warm."""
        self._t_ns = now_ns
        fx, fy, fz = self._cmd
        m = math.hypot(fx, fy, fz)
        if not math.isfinite(m):
            fx = fy = fz = 0.0
            m = 0.0
        elif m > self.spec.peak_force_n:
            k = self.spec.peak_force_n / m
            fx, fy, fz, m = fx * k, fy * k, fz * k, self.spec.peak_force_n
        if self.error_code:
            fx = fy = fz = 0.0
            m = 0.0
        self.heat_n2s = max(0.0, self.heat_n2s + (m * m - self.spec.continuous_force_n**2) * dt_s)
        if self.heat_n2s > self.spec.thermal_budget_n2s and not self.error_code:
            self.error_code = HD_WARM_MOTORS
            fx = fy = fz = 0.0
        self.applied_force_n = (fx, fy, fz)

    def rearm(self) -> bool:
        """Clear a device error if the motors have cooled to half the budget."""
        if self.error_code == HD_WARM_MOTORS and self.heat_n2s > 0.5 * self.spec.thermal_budget_n2s:
            return False
        self.error_code = 0
        return True

    def read_state(self) -> HapticState:
        """Stylus position (m, device frame), buttons and error code."""
        return HapticState(self._t_ns, self.stylus_m, self.buttons, self.error_code)

    def close(self) -> None:
        """Zero the output."""
        self._cmd = (0.0, 0.0, 0.0)
        self.applied_force_n = (0.0, 0.0, 0.0)
