"""The psychometric fit of a force-discrimination block: a participant's JND and Weber fraction at one reference.

Model (two-alternative forced choice, one value per participant per reference): the probability of a correct answer
at a comparison ``reference + Δ`` is

    P(Δ) = λ/2 + (1 − λ) · Φ(Δ / (√2 · J))

a cumulative Gaussian starting at chance (½) with a lapse rate ``λ`` (a lapse is a guess, right half the time).
``J`` is the **JND**: the Δ at which d′ = 1 (76 % correct without lapses; Macmillan & Creelman 2005) -- for an
observer whose percept of each force has SD σ it is σ itself, so the **Weber fraction** ``J / reference`` is the
percept's SD per newton (the simulated observer's ``W``, :mod:`pipeline.sim.discrimination_observer`).

Fitted by maximum likelihood over the block's (Δ, correct) trials, ``λ`` bounded to 0–6 % (Wichmann & Hill 2001:
an unbounded lapse trades against the slope; their bound); the **95 % interval** of ``J`` is the profile
likelihood's (the ``J`` whose likelihood, maximised over ``λ``, is within χ²₁(0.95)/2 = 1.92 log-units of the
maximum; Wichmann & Hill 2001 compare it with the bootstrap).  An interval that does not close within the grid's
range (a block that never discriminated) has that side NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize, minimize_scalar
from scipy.special import ndtr
from scipy.stats import chi2

__all__ = ["LAPSE_MAX", "PsychometricFit", "fit_psychometric", "p_correct"]

#: The lapse rate's upper bound (Wichmann & Hill 2001).
LAPSE_MAX = 0.06
#: The JND grid of the profile likelihood, as fractions of the reference: 0.2 % to 300 %, 600 log-spaced points.
_GRID = np.geomspace(0.002, 3.0, 600)
#: The profile likelihood's drop at the 95 % interval's edges (χ²₁ 0.95 quantile / 2).
_DROP = float(chi2.ppf(0.95, 1)) / 2.0
_TINY = 1e-12


def p_correct(delta_n: npt.ArrayLike, jnd_n: float, lapse: float) -> npt.NDArray[np.float64]:
    """The model's probability of a correct answer at each Δ (N)."""
    d = np.asarray(delta_n, dtype=np.float64)
    return np.asarray(lapse / 2.0 + (1.0 - lapse) * ndtr(d / (math.sqrt(2.0) * jnd_n)), dtype=np.float64)


def _nll(delta: npt.NDArray[np.float64], correct: npt.NDArray[np.bool_], jnd: float, lapse: float) -> float:
    p = np.clip(p_correct(delta, jnd, lapse), _TINY, 1.0 - _TINY)
    return -float(np.sum(np.where(correct, np.log(p), np.log1p(-p))))


@dataclass(frozen=True, slots=True)
class PsychometricFit:
    """One participant's fit at one reference (module docstring); forces in N at the hand."""

    reference_n: float
    n_trials: int
    n_correct: int
    jnd_n: float
    jnd_lo_n: float
    jnd_hi_n: float
    lapse: float

    @property
    def weber(self) -> float:
        """The Weber fraction: JND / reference."""
        return self.jnd_n / self.reference_n

    @property
    def weber_lo(self) -> float:
        return self.jnd_lo_n / self.reference_n

    @property
    def weber_hi(self) -> float:
        return self.jnd_hi_n / self.reference_n

    def curve(self, delta_n: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The fitted curve at each Δ (N)."""
        return p_correct(delta_n, self.jnd_n, self.lapse)


def _profile(delta: npt.NDArray[np.float64], correct: npt.NDArray[np.bool_], jnd: float) -> tuple[float, float]:
    """The negative log-likelihood at ``jnd`` minimised over the lapse rate, and that lapse rate."""
    r = minimize_scalar(lambda lam: _nll(delta, correct, jnd, lam), bounds=(0.0, LAPSE_MAX), method="bounded",
                        options={"xatol": 1e-5})
    return float(r.fun), float(r.x)


def fit_psychometric(reference_n: float, delta_n: npt.ArrayLike, correct: npt.ArrayLike) -> PsychometricFit:
    """The maximum-likelihood JND and lapse rate of a block's trials at one reference, with the JND's 95 % profile
    likelihood interval.

    Raises
    ------
    ValueError
        No trials, Δ and answers of different lengths, a Δ not finite and > 0, or a reference not > 0.
    """
    d = np.asarray(delta_n, dtype=np.float64)
    c = np.asarray(correct, dtype=np.bool_)
    if not (math.isfinite(reference_n) and reference_n > 0.0):
        raise ValueError(f"reference_n = {reference_n!r}: must be a finite force > 0 N")
    if d.ndim != 1 or d.shape != c.shape or len(d) == 0:
        raise ValueError(f"delta_n and correct: must be 1-D of one length ≥ 1, got shapes {d.shape} and {c.shape}")
    if not np.all(np.isfinite(d) & (d > 0.0)):
        raise ValueError("delta_n: every Δ must be finite and > 0 N (the comparison is the stronger force)")
    grid = _GRID * reference_n
    prof = np.array([_profile(d, c, j)[0] for j in grid])
    k = int(np.argmin(prof))
    lam0 = _profile(d, c, grid[k])[1]
    best = minimize(lambda x: _nll(d, c, math.exp(x[0]), x[1]), x0=[math.log(grid[k]), lam0], method="L-BFGS-B",
                    bounds=[(math.log(grid[0]), math.log(grid[-1])), (0.0, LAPSE_MAX)])
    jnd, lapse, nll = math.exp(best.x[0]), float(best.x[1]), float(best.fun)
    if nll > prof[k]:  # (the optimiser never does worse than the grid's best point)
        jnd, lapse, nll = float(grid[k]), lam0, float(prof[k])
    inside = prof - nll <= _DROP
    lo, hi = _edge(grid, prof - nll, inside, side=-1, at=k), _edge(grid, prof - nll, inside, side=1, at=k)
    return PsychometricFit(reference_n, int(len(d)), int(np.sum(c)), jnd, lo, hi, lapse)


def _edge(grid: npt.NDArray[np.float64], rise: npt.NDArray[np.float64], inside: npt.NDArray[np.bool_], *, side: int,
          at: int) -> float:
    """The interval's edge on one side of the grid's best point ``at``: where the profile's rise crosses the drop,
    interpolated in log J between the last point inside and the first outside (NaN: it never leaves)."""
    k = at
    while 0 <= k + side < len(grid) and inside[k + side]:
        k += side
    if not 0 <= k + side < len(grid):
        return math.nan
    a, b = rise[k], rise[k + side]
    w = (_DROP - a) / (b - a) if b != a else 0.0
    return float(math.exp(math.log(grid[k]) + w * (math.log(grid[k + side]) - math.log(grid[k]))))
