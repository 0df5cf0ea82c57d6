"""Online refinement of the force/torque sensor's bias while the tool is out of contact (science.md §1.4).

The offline calibration (:mod:`pipeline.commissioning.payload_identification`) fixes mass,
centre of mass and mount; only the bias drifts (with temperature, §1.5), and
:class:`RlsBias` follows it from samples the loop knows to be contact-free.
Its update is a compiled kernel over the estimator's float64 array (:func:`rls_update`), which Algorithm 1's
compiled refinement step calls too (:func:`pipeline.force.framework.refine_kernel`): it runs in the 1 kHz loop.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from pipeline.core.compiled import KernelState, State, kernel, warm_once
from pipeline.force.frames import Vec3
from pipeline.force.payload_compensator import finite_tuple

__all__ = ["COVARIANCE", "STATE_SIZE", "THETA", "RlsBias", "rls_update"]

# The estimator's state, one float64 array: the six offsets (force N, torque N·m), P, the forgetting factor, P's
# start and bound, the squared contact gate, and the counts of updates and refused samples (exact below 2**53).
_TH, _P, _LAM, _P0, _PMAX, _GATE2, _UPDATES, _REJECTED = 0, 6, 7, 8, 9, 10, 11, 12
#: The length of the estimator's array, where its six offsets start, and where its P is.
STATE_SIZE, THETA, COVARIANCE = 13, _TH, _P


@kernel
def rls_update(r: State, fx: float, fy: float, fz: float, tx: float, ty: float, tz: float) -> bool:
    """:meth:`RlsBias.update` of an allowed sample (the wrench minus the payload's weight) over the array ``r``."""
    ex, ey, ez = fx - r[0], fy - r[1], fz - r[2]
    etx, ety, etz = tx - r[3], ty - r[4], tz - r[5]
    # NaN fails both comparisons, so a corrupt sample is refused too
    if not (ex * ex + ey * ey + ez * ez < r[_GATE2] and abs(etx) + abs(ety) + abs(etz) < math.inf):
        r[_REJECTED] += 1.0
        return False
    p = r[_P]
    k = p / (r[_LAM] + p)
    r[0] += k * ex
    r[1] += k * ey
    r[2] += k * ez
    r[3] += k * etx
    r[4] += k * ety
    r[5] += k * etz
    p = (p - k * p) / r[_LAM]
    r[_P] = p if p < r[_PMAX] else r[_PMAX]
    r[_UPDATES] += 1.0
    return True


class RlsBias(KernelState):
    """Recursive least-squares refinement of the 6 sensor offsets (science.md §1.4).

    Mass and centre of mass stay at their offline values; only the bias, the
    part that drifts with temperature (§1.5), adapts.  The bias regressor is
    the identity, so the 6-channel RLS decouples into 6 scalar recursions

    ``e = z − θ;  K = P/(λ + P);  θ ← θ + K e;  P ← min((P − K P)/λ, p_max)``

    All channels share the regressor, the prior ``p0`` and the update instants,
    so their ``P`` are identical; one ``P`` is kept for all six.

    Parameters
    ----------
    initial_force_bias_n, initial_torque_bias_nm
        Starting offsets (N, N·m), normally from the offline calibration.
    forgetting
        λ in (0, 1].  The memory is ``1/(1 − λ)`` updates: at 1 kHz the
        default 0.9995 remembers 2000 samples = 2 s, 0.999 → 1 s, 0.9999 → 10 s;
        λ = 1 never forgets (a running mean).
    p0
        Initial covariance (dimensionless gain scale), 0 < p0 ≤ p_max.  The
        first gain is ``p0/(λ + p0)`` (≈ 0.01 by default: the initial offsets
        are trusted like ~100 samples).
    p_max
        Upper clamp on ``P`` against covariance wind-up.
    gate_force_n
        Contact guard: a sample whose force innovation ``|e_f|`` is not below
        this (N) is ignored, even when the caller allows updates.  ``inf``
        disables the guard.

    Notes
    -----
    With this identity regressor every update excites every parameter, so
    ``P`` cannot wind up while updates happen: it converges monotonically to
    ``1 − λ``, where the filter becomes an exponential average with gain
    ``1 − λ`` (time constant ``1/(1 − λ)`` samples).  ``P`` is frozen while
    updates are not allowed (no information, so no forgetting either): a long
    trial therefore does not inflate the gain of the first sample after it.
    ``p_max`` bounds ``P`` for the remaining cases (``p_max < 1 − λ``).

    The gate compares against the current estimate, so a bias jump larger
    than ``gate_force_n`` is never followed; :attr:`rejected` counts such
    samples, and a growing count at rest means: re-bias offline.
    """

    __slots__ = ()

    def __init__(
        self,
        initial_force_bias_n: Sequence[float],
        initial_torque_bias_nm: Sequence[float],
        forgetting: float = 0.9995,
        p0: float = 1e-2,
        p_max: float = 1.0,
        gate_force_n: float = 0.15,
    ) -> None:
        fb = finite_tuple(initial_force_bias_n, 3, "initial_force_bias_n")
        tb = finite_tuple(initial_torque_bias_nm, 3, "initial_torque_bias_nm")
        if not (isinstance(forgetting, (int, float)) and 0.0 < forgetting <= 1.0):
            raise ValueError(f"forgetting = {forgetting!r}: must be in (0, 1] (memory 1/(1 − forgetting) samples)")
        if not (isinstance(p_max, (int, float)) and 0.0 < p_max < math.inf):
            raise ValueError(f"p_max = {p_max!r}: must be a finite number > 0")
        if not (isinstance(p0, (int, float)) and 0.0 < p0 <= p_max):
            raise ValueError(f"p0 = {p0!r}: must be > 0 and ≤ p_max = {p_max!r}")
        if not (isinstance(gate_force_n, (int, float)) and gate_force_n > 0.0):
            raise ValueError(f"gate_force_n = {gate_force_n!r}: must be > 0 N (inf disables the gate)")
        #: The state as :func:`rls_update` reads it.
        self.array: State = np.zeros(STATE_SIZE)
        r = self.array
        r[_LAM], r[_P0], r[_PMAX], r[_GATE2] = float(forgetting), float(p0), float(p_max), float(gate_force_n) ** 2
        r[_TH:_TH + 6] = (*fb, *tb)
        r[_P] = r[_P0]
        _warm(r)

    @property
    def updates(self) -> int:
        """Number of samples that updated the estimate."""
        return int(self.array[_UPDATES])

    @property
    def rejected(self) -> int:
        """Number of allowed samples refused by the contact gate (or non-finite)."""
        return int(self.array[_REJECTED])

    def reset(self, force_bias_n: Sequence[float], torque_bias_nm: Sequence[float]) -> None:
        """Restart from new offsets (e.g. after a re-bias at rest) with ``P = p0``."""
        fb = finite_tuple(force_bias_n, 3, "force_bias_n")
        tb = finite_tuple(torque_bias_nm, 3, "torque_bias_nm")
        r = self.array
        r[_TH:_TH + 6] = (*fb, *tb)
        r[_P] = r[_P0]
        r[_UPDATES] = r[_REJECTED] = 0.0

    def update(self, wrench_minus_gravity: Sequence[float], allowed: bool) -> bool:
        """Feed one sample; return whether it updated the estimate.

        Parameters
        ----------
        wrench_minus_gravity
            Measured wrench minus the payload weight only
            (:meth:`PayloadCalibration.payload_wrench`), N and N·m: out of
            contact it equals bias + noise.
        allowed
            True when the caller knows the tool is out of contact (not in a
            trial, not near tissue, low acceleration).  Contact absorbed into
            the bias would cancel exactly the force the user should feel.

        Returns
        -------
        bool
            True if the sample was used.
        """
        if not allowed:
            return False
        fx, fy, fz, tx, ty, tz = (float(v) for v in wrench_minus_gravity)
        return bool(rls_update(self.array, fx, fy, fz, tx, ty, tz))

    @property
    def force_bias_n(self) -> Vec3:
        """Current force offset estimate, N."""
        r = self.array
        return (float(r[0]), float(r[1]), float(r[2]))

    @property
    def torque_bias_nm(self) -> Vec3:
        """Current torque offset estimate, N·m."""
        r = self.array
        return (float(r[3]), float(r[4]), float(r[5]))

    @property
    def covariance(self) -> float:
        """Current ``P`` (the same for all six channels)."""
        return float(self.array[_P])

    def state(self) -> dict[str, Any]:
        """Everything that determines the next update, JSON-safe and exact (see :meth:`from_state`)."""
        r = self.array
        return {"forgetting": float(r[_LAM]), "p0": float(r[_P0]), "p_max": float(r[_PMAX]),
                "gate2": float(r[_GATE2]), "theta": [float(v) for v in r[_TH:_TH + 6]], "p": float(r[_P]),
                "updates": self.updates, "rejected": self.rejected}

    @classmethod
    def from_state(cls, d: Mapping[str, Any]) -> RlsBias:
        """The estimator exactly as :meth:`state` saw it."""
        th = [float(v) for v in d["theta"]]
        rls = cls(th[:3], th[3:], forgetting=float(d["forgetting"]), p0=float(d["p0"]), p_max=float(d["p_max"]))
        r = rls.array
        r[_GATE2], r[_P] = float(d["gate2"]), float(d["p"])
        r[_UPDATES], r[_REJECTED] = int(d["updates"]), int(d["rejected"])
        return rls


def _warm(array: State) -> None:
    """Compile :func:`rls_update` (or load it from numba's cache) once a process, on a copy of an estimator's state."""
    warm_once(__name__, lambda: rls_update(array.copy(), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
