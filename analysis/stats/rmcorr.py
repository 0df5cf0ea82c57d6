"""The repeated-measures correlation (Bakdash & Marusich 2017, "rmcorr"): one within-participant association.

Trials of one participant are not independent, so a correlation over pooled trials has a p-value that is
wrong by construction (pseudo-replication).  rmcorr asks what a reviewer asks: *within* a participant, do
two measures move together?  It is the ANCOVA ``y ~ participant + x`` -- one common slope, a separate
intercept per participant -- read as a correlation:

    r_rm = sign(b) · √(SS_x / (SS_x + SS_residual)),   df = N − k − 1

(N observations, k participants), with the p-value of the slope's t test (the type III F test of x).  The
ANCOVA's slope and residuals are those of the participant-centred data (x̃ = x − its participant's mean,
likewise ỹ; the Frisch–Waugh–Lovell theorem), so r_rm = Σx̃ỹ / √(Σx̃² Σỹ²) and t = r_rm √(df / (1 − r_rm²)):
computed so here, in O(N), because a design matrix with one column per participant does not fit in memory
for 10 000 simulated participants.  The test suite checks it against the ANCOVA fitted by statsmodels' OLS.
The interval is Fisher's z of a partial correlation: r_rm is the correlation of x and y with the k − 1
participant contrasts partialled out, and Fisher's z of a partial correlation over N observations with q
variables partialled out has SE = 1/√(N − q − 3) = 1/√(df − 1) -- pingouin's ``rm_corr`` (a Pearson interval at
n = df + 2), defined for df ≥ 2.  The rmcorr R package takes df for n (``psych::r.con(r, df)``: SE = 1/√(df − 3))
and so gives a wider interval, the more so the smaller df: at df = 4 it covers a true r_rm in 99.8 % of simulated
studies where 95 % is claimed, at df = 3 it has none; this one covers 95 % at every df (docs/science.md §6.1).
On the R package's example (``bland1995``, Bland & Altman 1995) r_rm = −0.5067697, df = 38 and p = 0.0008471
are the R package's; the 95 % CI is pingouin's (−0.7067, −0.2319), the R package printing (−0.7112, −0.2233).
The test suite checks both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import special
from scipy import stats as sps

from analysis.stats.correlation import unit_snapped
from protocol.study.labels import plural

__all__ = ["MIN_INTERVAL_DF", "RmCorrResult", "rmcorr"]


@dataclass(frozen=True, slots=True)
class RmCorrResult:
    """A repeated-measures correlation.

    Attributes
    ----------
    r : float
        The repeated-measures correlation r_rm, in [−1, 1].
    df : int
        Its degrees of freedom, N − k − 1.
    p_value : float
        Two-sided p of H0: no common within-participant association (the slope's t test, df = ``df``).
    ci_low, ci_high : float
        Fisher-z interval at ``ci_level`` with SE = 1/√(df − 1), as pingouin's ``rm_corr``; NaN when df < 2.
    ci_level : float
        Nominal level of the interval.
    slope : float
        The common within-participant slope of y on x (units of y per unit of x).
    slope_se : float
        Its standard error.
    n_obs, n_participants : int
        Observations and participants used (participants with a single observation carry no within-participant
        information and are left out, as they would contribute nothing but a parameter).
    n_dropped : int
        Observations left out: a NaN in either measure, or their participant's only observation.
    computable : bool
        False when there is nothing to correlate (df < 1, or x or y constant within every participant).
    note : str
        Why not computable, or what was left out; empty otherwise.
    """

    r: float
    df: int
    p_value: float
    ci_low: float
    ci_high: float
    ci_level: float
    slope: float
    slope_se: float
    n_obs: int
    n_participants: int
    n_dropped: int
    computable: bool
    note: str


#: The least df with an interval: at df = 1 the partial correlation's z has no finite SE (its interval is all of
#: [−1, 1], which pingouin reaches through a division by zero).
MIN_INTERVAL_DF = 2


def _interval(r: float, df: int, confidence: float) -> tuple[float, float]:
    """Fisher's z interval of r_rm as a partial correlation, SE = 1/√(df − 1) (pingouin's); NaN for df < 2."""
    if df < MIN_INTERVAL_DF:
        return math.nan, math.nan
    if abs(r) >= 1.0:
        return r, r
    zq = float(special.ndtri(0.5 + confidence / 2.0))
    z, se = math.atanh(r), 1.0 / math.sqrt(df - 1)
    return math.tanh(z - zq * se), math.tanh(z + zq * se)


def _left_out(n_nan: int, n_single: int) -> str:
    """The note of what was left out: observations with a NaN, participants with a single observation."""
    return "; ".join(part for part in (
        f"{n_nan} observations with a NaN left out" if n_nan else "",
        f"{plural(n_single, 'participant')} with a single observation left out (no within-participant information)"
        if n_single else "") if part)


def rmcorr(participant: npt.ArrayLike, x: npt.ArrayLike, y: npt.ArrayLike, *,
           confidence: float = 0.95) -> RmCorrResult:
    """The repeated-measures correlation of ``x`` and ``y`` observed repeatedly within participants.

    Parameters
    ----------
    participant : array_like
        Who each observation belongs to (any hashable labels).
    x, y : array_like of float
        The two measures, one pair per observation.  Pairs with a NaN are left out and counted.
    confidence : float
        Level of the confidence interval.

    Returns
    -------
    RmCorrResult

    Raises
    ------
    ValueError
        Lengths differ, or ``confidence`` is not in (0, 1).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence = {confidence}: allowed is 0 < confidence < 1")
    who = np.asarray(participant)
    xa = np.asarray(x, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    if not (who.shape == xa.shape == ya.shape) or xa.ndim != 1:
        raise ValueError(f"participant, x and y must be 1-D of equal length, got {who.shape}, {xa.shape}, {ya.shape}")
    keep = np.isfinite(xa) & np.isfinite(ya)
    _, codes, counts = np.unique(who[keep], return_inverse=True, return_counts=True)
    several = counts[codes] >= 2  # a participant's only observation carries no within-participant information
    idx = np.flatnonzero(keep)[several]
    groups = np.unique(codes[several])
    n, k = len(idx), len(groups)
    dropped = len(xa) - n
    nan = math.nan
    note = _left_out(int((~keep).sum()), int((~several).sum()))

    def fail(why: str) -> RmCorrResult:
        return RmCorrResult(nan, max(n - k - 1, 0), nan, nan, nan, confidence, nan, nan, n, k, dropped, False,
                            "; ".join(part for part in (note, why) if part))

    df = n - k - 1
    if df < 1:
        return fail(f"{plural(n, 'observation')} of {plural(k, 'participant')} leave{'s' if n == 1 else ''} "
                    f"{plural(df, 'degree')} of freedom: at least 1 is needed "
                    "(two participants with two observations each, or one with three)")
    xs, ys = xa[idx], ya[idx]
    member = np.searchsorted(groups, codes[several])
    size = np.bincount(member)
    xt = xs - (np.bincount(member, xs) / size)[member]  # within-participant deviations
    yt = ys - (np.bincount(member, ys) / size)[member]
    sxx, syy, sxy = float(xt @ xt), float(yt @ yt), float(xt @ yt)
    # what centring leaves of a constant by rounding alone: a few ulps of the largest value per observation
    def flat(s: float, v: npt.NDArray[np.float64]) -> bool:
        return bool(s <= len(v) * (64.0 * np.finfo(np.float64).eps * float(np.abs(v).max())) ** 2)

    if flat(sxx, xs):
        return fail("x does not vary within any participant: there is no within-participant slope")
    if flat(syy, ys):
        return fail("y does not vary within any participant: there is no within-participant association")
    b = sxy / sxx
    # a perfect line is r_rm = ±1 with p 0 on every CPU: within UNIT_R_TOLERANCE of ±1 (its dot products' last bit
    # depends on the BLAS kernel) it is made ±1, and a ratio rounded beyond ±1 is clipped; the square roots taken
    # apart, as a product of two tiny sums of squares underflows to 0 (values near 1e-133 and 1e-38)
    r = unit_snapped(sxy / (math.sqrt(sxx) * math.sqrt(syy)))
    ss_res = max(syy - b * sxy, 0.0)
    se_b = math.sqrt(ss_res / df / sxx)
    # a perfect line's t is infinite: its p is 0 (so on every CPU, r being snapped above)
    p = 0.0 if abs(r) == 1.0 else float(2.0 * sps.t.sf(abs(r) * math.sqrt(df / (1.0 - r * r)), df))
    lo, hi = _interval(r, df, confidence)
    if df < MIN_INTERVAL_DF:
        note = "; ".join(part for part in (note, f"df = {df}: no interval (needs df ≥ {MIN_INTERVAL_DF})") if part)
    # p clipped into [0, 1] (a doubled tail can round past 1)
    return RmCorrResult(float(r), df, min(max(float(p), 0.0), 1.0), lo, hi, confidence, b, se_b, n, k, dropped,
                        True, note)
