"""Hunt–Crossley soft-tissue contact along the surface normal (science.md §3).

``F = k δⁿ (1 + α δ̇)`` for penetration ``δ > 0``, clamped at ``F ≥ 0`` (no
adhesion when the tool retracts fast).  Unlike Kelvin–Voigt the force is
continuous at first contact.  With the defaults (n = 1.5, k = 1.1e4 N/m^1.5)
the task forces are reached at about 1.4 mm (0.6 N) and 2.3 mm (1.2 N) of
indentation: the visual difference between GENTLE and FIRM is under 1 mm.

An optional Maxwell branch adds stress relaxation
(``Ḟ_M = k_M δ̇ − F_M/τ_M``), which makes a frozen hand lose force during a hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.core.compiled import KernelState, State, kernel

__all__ = ["HuntCrossleyTissue", "TissueParams"]


@dataclass(frozen=True, slots=True)
class TissueParams:
    """Contact parameters.

    Attributes
    ----------
    stiffness_n_per_m_pow
        ``k``, N/mⁿ.
    exponent
        ``n`` (1.5 for a rounded tip by Hertz contact).
    damping_s_per_m
        ``α = λ/k``, s/m (0.2–0.5; minor at hand speeds).
    relax_stiffness_n_per_m
        Maxwell branch stiffness ``k_M``, N/m (0 disables relaxation).
    relax_time_s
        Maxwell time constant ``τ_M``, s.
    """

    stiffness_n_per_m_pow: float = 1.1e4
    exponent: float = 1.5
    damping_s_per_m: float = 0.3
    relax_stiffness_n_per_m: float = 0.0
    relax_time_s: float = 2.0

    def __post_init__(self) -> None:
        for name in ("stiffness_n_per_m_pow", "exponent", "relax_time_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"tissue.{name} = {v!r}: must be a finite number > 0")
        for name in ("damping_s_per_m", "relax_stiffness_n_per_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"tissue.{name} = {v!r}: must be a finite number ≥ 0")

    def depth_for_force(self, force_n: float) -> float:
        """Static indentation (m) that produces ``force_n`` (inverse of ``k δⁿ``)."""
        if force_n <= 0:
            return 0.0
        return float((force_n / self.stiffness_n_per_m_pow) ** (1.0 / self.exponent))

    def static_force(self, depth_m: float) -> float:
        """Elastic force ``k δⁿ`` at rest, N."""
        return self.stiffness_n_per_m_pow * depth_m**self.exponent if depth_m > 0 else 0.0


# The tissue's state, a float64 array (its kernel's layout): the last penetration, the Maxwell branch's force, the
# contact force of the last step, and the parameters.
_PREV, _MAXWELL, _FORCE, _K, _N, _DAMPING, _RELAX_K, _RELAX_TAU = 0, 1, 2, 3, 4, 5, 6, 7
STATE_SIZE = 8


@kernel
def step_kernel(st: State, depth_m: float, dt_s: float) -> float:
    """Advance by ``dt_s`` with penetration ``depth_m`` (≤ 0: no contact); return the force, N."""
    rate = (depth_m - st[_PREV]) / dt_s if dt_s > 0 else 0.0
    st[_PREV] = depth_m
    if depth_m <= 0.0:
        st[_MAXWELL] = 0.0
        st[_FORCE] = 0.0
        return 0.0
    elastic = st[_K] * depth_m ** st[_N]
    f = elastic * (1.0 + st[_DAMPING] * rate)
    if st[_RELAX_K] > 0.0 and dt_s > 0:
        # exact update of Ḟ_M = k_M δ̇ − F_M/τ_M over one step at constant δ̇
        decay = math.exp(-dt_s / st[_RELAX_TAU])
        fm = st[_MAXWELL] * decay + st[_RELAX_K] * rate * st[_RELAX_TAU] * (1.0 - decay)
        st[_MAXWELL] = fm
        f += fm
    f = f if f > 0.0 else 0.0
    st[_FORCE] = f
    return f


class HuntCrossleyTissue(KernelState):
    """Stateful tissue: call :meth:`step` with the tip penetration each tick (:func:`step_kernel`, compiled, over the
    state array :attr:`array`, which the rig's compiled step works on too)."""

    __slots__ = ("_params",)

    def __init__(self, params: TissueParams | None = None) -> None:
        self._params = p = params or TissueParams()
        #: The state :func:`step_kernel` works on (the rig may move it into
        #: its own array: :meth:`~pipeline.core.compiled.KernelState.adopt`).
        self.array = np.array([0.0, 0.0, 0.0, p.stiffness_n_per_m_pow, p.exponent, p.damping_s_per_m,
                               p.relax_stiffness_n_per_m, p.relax_time_s])

    @property
    def params(self) -> TissueParams:
        """The tissue's parameters (read-only: they are in :attr:`array`)."""
        return self._params

    @property
    def force_n(self) -> float:
        """The contact force of the last step, N (≥ 0)."""
        return float(self.array[_FORCE])

    def step(self, depth_m: float, dt_s: float) -> float:
        """Advance by ``dt_s`` with penetration ``depth_m`` (≤ 0: no contact); return the force, N."""
        return step_kernel(self.array, float(depth_m), float(dt_s))
