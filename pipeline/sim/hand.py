"""The hand on the stylus: a compliant arm driven toward an equilibrium point (science.md §4.2 item 1).

Along the tissue normal (up; the haptic device's axis along it is its +y with the paper's frames,
:attr:`pipeline.sim.rig.SimRig.hand_axis`)::

    m_a ÿ = K_a (y_c − y) − B_a ẏ + f_H,y

with K_a = 500 N/m, B_a = 10 N·s/m, m_a = 0.25 kg.  With feedback on, the
rendered force physically pushes the hand back (the Wagner–Howe mechanism by
which force feedback prevents excessive force).  Who chooses the equilibrium
point ``y_c`` is a :class:`StylusDriver`: a scripted press pattern here, the
simulated participant of the study (``pipeline.sim.participant``), or a person
with the mouse in the GUI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np

from pipeline.core.compiled import KernelState, State, kernel

__all__ = ["ArmParams", "CompliantArm", "HandObservation", "HoldStill", "ScriptedPresses", "StylusDriver", "min_jerk"]


class HandObservation(NamedTuple):
    """What the person holding the stylus can sense this tick.

    ``indentation_m`` is the tissue indentation visible on the camera image
    (the only cue with haptics OFF); ``felt_force_n`` the rendered force along
    +y (0 with haptics OFF); ``stylus_y_m`` the hand position relative to the
    start pose (proprioception); ``gap_m`` the visible tip-to-surface gap.
    """

    t_s: float
    stylus_y_m: float
    felt_force_n: float
    indentation_m: float
    gap_m: float


class StylusDriver(Protocol):
    """Chooses where the hand wants the stylus to be."""

    def equilibrium_y(self, obs: HandObservation) -> float:
        """Equilibrium point ``y_c`` of the arm, m along the Touch's +y axis (relative to start)."""
        ...


@dataclass(frozen=True, slots=True)
class ArmParams:
    """Arm impedance (science.md §4.2)."""

    stiffness_n_per_m: float = 500.0
    damping_ns_per_m: float = 10.0
    mass_kg: float = 0.25


# The arm's state, a float64 array (its kernels' layout): position and velocity along y, then its impedance.
_Y, _V, _K, _B, _M = 0, 1, 2, 3, 4
STATE_SIZE = 5


@kernel
def step_kernel(st: State, y_c: float, felt_force_n: float, dt_s: float) -> float:
    """Advance by ``dt_s`` toward ``y_c`` under the felt force; return the new position (:class:`CompliantArm`)."""
    if dt_s / 0.001 <= 1.0:
        # one sub-step (every tick of a 1 kHz loop): substeps_kernel(..., 1) without its loop, the same arithmetic
        v = st[_V] + (st[_K] * (y_c - st[_Y]) - st[_B] * st[_V] + felt_force_n) / st[_M] * dt_s
        st[_V] = v
        y: float = st[_Y] + v * dt_s
        st[_Y] = y
        return y
    # integrate in sub-steps of ≤ 1 ms so a long tick stays stable
    return substeps_kernel(st, y_c, felt_force_n, dt_s, max(1, int(math.ceil(dt_s / 0.001))))


@kernel
def substeps_kernel(st: State, y_c: float, felt_force_n: float, dt_s: float, n: int) -> float:
    """Advance by ``dt_s`` in ``n`` equal semi-implicit Euler steps; return the new position."""
    h = dt_s / n
    for _ in range(n):
        a = (st[_K] * (y_c - st[_Y]) - st[_B] * st[_V] + felt_force_n) / st[_M]
        st[_V] += a * h
        st[_Y] += st[_V] * h
    y: float = st[_Y]
    return y


class CompliantArm(KernelState):
    """Integrates the arm along y with semi-implicit Euler (stable at 1 kHz: ω ≈ 45 rad/s): :func:`step_kernel`,
    compiled, over the state array :attr:`array` (which the rig's compiled step works on too)."""

    __slots__ = ("_params",)

    def __init__(self, params: ArmParams | None = None) -> None:
        self._params = p = params or ArmParams()
        #: The state the kernels work on (the rig may move it into
        #: its own array: :meth:`~pipeline.core.compiled.KernelState.adopt`).
        self.array = np.array([0.0, 0.0, p.stiffness_n_per_m, p.damping_ns_per_m, p.mass_kg])

    @property
    def params(self) -> ArmParams:
        """The arm's impedance (read-only: it is in :attr:`array`)."""
        return self._params

    @property
    def y_m(self) -> float:
        """Position along y, m."""
        return float(self.array[_Y])

    @property
    def v_m_s(self) -> float:
        """Velocity along y, m/s."""
        return float(self.array[_V])

    def step(self, y_c: float, felt_force_n: float, dt_s: float) -> float:
        """Advance by ``dt_s`` toward ``y_c`` under the felt force; return the new position."""
        if dt_s != dt_s or dt_s == math.inf:  # (how many sub-steps: as many as ceil() of it, which has none)
            raise ValueError(f"dt_s = {dt_s!r}: must be a finite number of seconds")
        return step_kernel(self.array, float(y_c), float(felt_force_n), float(dt_s))

    def substeps(self, y_c: float, felt_force_n: float, dt_s: float, n: int) -> float:
        """Advance by ``dt_s`` in ``n`` equal semi-implicit Euler steps; return the new position."""
        return substeps_kernel(self.array, float(y_c), float(felt_force_n), float(dt_s), int(n))


@kernel
def min_jerk(t: float, t0: float, duration: float, y0: float, y1: float) -> float:
    """Minimum-jerk interpolation from ``y0`` at ``t0`` to ``y1`` at ``t0 + duration`` (floats only: compiled)."""
    if t <= t0:
        return y0
    if t >= t0 + duration:
        return y1
    s = (t - t0) / duration
    # float exponents: the C library's pow, as Python's ** calls it (numba would multiply out an int exponent)
    return float(y0 + (y1 - y0) * (10.0 * s**3.0 - 15.0 * s**4.0 + 6.0 * s**5.0))


class HoldStill:
    """Keep the stylus where it is (calibration, idle)."""

    def __init__(self, y_m: float = 0.0) -> None:
        self.y_m = y_m

    def equilibrium_y(self, obs: HandObservation) -> float:
        """Constant equilibrium."""
        return self.y_m


class ScriptedPresses:
    """Repeated press–hold–release cycles to given indentations (a demo and test driver).

    Each cycle of ``period_s``: rest for ``rest_s``, a 0.6 s minimum-jerk
    move to the indentation, hold, release in 0.4 s.  Equilibrium targets
    include the arm's static deflection under the felt force, so the
    indentation is about right whether feedback is on or off.
    """

    def __init__(
        self,
        depths_m: tuple[float, ...] = (0.0014, 0.0023),
        start_gap_m: float = 0.015,
        period_s: float = 4.0,
        rest_s: float = 1.0,
        hold_s: float = 1.8,
        arm_stiffness_n_per_m: float = 500.0,
        expected_push_n: tuple[float, ...] = (0.0, 0.0),
    ) -> None:
        self.depths_m = depths_m
        self.start_gap_m = start_gap_m
        self.period_s = period_s
        self.rest_s = rest_s
        self.hold_s = hold_s
        self.k = arm_stiffness_n_per_m
        self.expected_push_n = expected_push_n

    def equilibrium_y(self, obs: HandObservation) -> float:
        """Piecewise minimum-jerk press pattern."""
        k = int(obs.t_s // self.period_s)
        tc = obs.t_s - k * self.period_s
        i = k % len(self.depths_m)
        bottom = -(self.start_gap_m + self.depths_m[i]) - obs.felt_force_n / self.k
        t_down = self.rest_s
        t_up = self.rest_s + 0.6 + self.hold_s
        # (float(): the kernel is compiled for floats; an int period or rest would compile another version)
        if tc < t_up:
            return min_jerk(float(tc), float(t_down), 0.6, 0.0, float(bottom))
        return min_jerk(float(tc), float(t_up), 0.4, float(bottom), 0.0)
