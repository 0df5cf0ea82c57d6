"""Online refinement of the force/torque sensor's bias while the tool is out of contact (science.md §1.4).

The offline calibration (:mod:`pipeline.commissioning.payload_identification`) fixes mass,
centre of mass and mount; only the bias drifts (with temperature, §1.5), and
:class:`RlsBias` follows it from samples the loop knows to be contact-free.
Plain float arithmetic: it runs in the 1 kHz loop.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from pipeline.force.frames import Vec3
from pipeline.force.payload_compensator import finite_tuple

__all__ = ["RlsBias"]


class RlsBias:
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

    __slots__ = ("_gate2", "_lam", "_p", "_p0", "_p_max", "_theta", "rejected", "updates")

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
        self._lam = float(forgetting)
        self._p0 = float(p0)
        self._p_max = float(p_max)
        self._gate2 = float(gate_force_n) ** 2
        self._theta = [*fb, *tb]
        self._p = self._p0
        #: Number of samples that updated the estimate.
        self.updates = 0
        #: Number of allowed samples refused by the contact gate (or non-finite).
        self.rejected = 0

    def reset(self, force_bias_n: Sequence[float], torque_bias_nm: Sequence[float]) -> None:
        """Restart from new offsets (e.g. after a re-bias at rest) with ``P = p0``."""
        fb = finite_tuple(force_bias_n, 3, "force_bias_n")
        self._theta = [*fb, *finite_tuple(torque_bias_nm, 3, "torque_bias_nm")]
        self._p = self._p0
        self.updates = 0
        self.rejected = 0

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
        th = self._theta
        fx, fy, fz, tx, ty, tz = wrench_minus_gravity
        ex, ey, ez = fx - th[0], fy - th[1], fz - th[2]
        etx, ety, etz = tx - th[3], ty - th[4], tz - th[5]
        # NaN fails both comparisons, so a corrupt sample is refused too
        if not (ex * ex + ey * ey + ez * ez < self._gate2 and abs(etx) + abs(ety) + abs(etz) < math.inf):
            self.rejected += 1
            return False
        p = self._p
        k = p / (self._lam + p)
        th[0] += k * ex
        th[1] += k * ey
        th[2] += k * ez
        th[3] += k * etx
        th[4] += k * ety
        th[5] += k * etz
        p = (p - k * p) / self._lam
        self._p = p if p < self._p_max else self._p_max
        self.updates += 1
        return True

    @property
    def force_bias_n(self) -> Vec3:
        """Current force offset estimate, N."""
        th = self._theta
        return (th[0], th[1], th[2])

    @property
    def torque_bias_nm(self) -> Vec3:
        """Current torque offset estimate, N·m."""
        th = self._theta
        return (th[3], th[4], th[5])

    @property
    def covariance(self) -> float:
        """Current ``P`` (the same for all six channels)."""
        return self._p

    def state(self) -> dict[str, Any]:
        """Everything that determines the next update, JSON-safe and exact (see :meth:`from_state`)."""
        return {"forgetting": self._lam, "p0": self._p0, "p_max": self._p_max, "gate2": self._gate2,
                "theta": list(self._theta), "p": self._p, "updates": self.updates, "rejected": self.rejected}

    @classmethod
    def from_state(cls, d: Mapping[str, Any]) -> RlsBias:
        """The estimator exactly as :meth:`state` saw it."""
        th = [float(v) for v in d["theta"]]
        rls = cls(th[:3], th[3:], forgetting=float(d["forgetting"]), p0=float(d["p0"]), p_max=float(d["p_max"]))
        rls._gate2 = float(d["gate2"])
        rls._p = float(d["p"])
        rls.updates, rls.rejected = int(d["updates"]), int(d["rejected"])
        return rls
