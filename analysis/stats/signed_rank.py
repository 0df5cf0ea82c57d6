"""The signed-rank statistic's null distributions and SciPy's ``method="auto"`` rule.

:func:`analysis.stats.wilcoxon.paired_wilcoxon` computes its tests with
:func:`scipy.stats.wilcoxon`; what lives here is what SciPy does not offer as
a public function and two other rooms need:

* :func:`signed_rank_null_counts` -- the exact null distribution of W⁺ for n
  untied, non-zero differences, counted with integers.  The Hodges–Lehmann
  interval (:mod:`analysis.stats.hodges_lehmann`) takes its critical ranks from it,
  and the power analysis (:mod:`analysis.stats.resampled_wilcoxon`) its exact p-values.
* :func:`sign_flip_distribution` -- the exact sign-flip distribution of given
  (doubled mid-)ranks: the permutation test with ties and zeros, for the power
  analysis, which runs the report's test on thousands of resampled studies at
  once (tests/analysis/test_power.py proves it equal to ``paired_wilcoxon``).
* :func:`auto_method` -- which method SciPy's ``method="auto"`` uses, so the
  report can name it.  The rule is that of SciPy 1.15 – 1.17
  (``scipy/stats/_wilcoxon.py``, unchanged across these releases; ``pyproject.toml``
  pins this range): more than :data:`EXACT_MAX_N` pairs → the normal
  approximation; otherwise no ties and no zeros → the exact distribution;
  otherwise at most :data:`PERMUTATION_AUTO_MAX_N` pairs → the permutation test
  (all 2ⁿ sign flips); otherwise → the normal approximation.  "Pairs" counts
  zero differences too.
* :func:`report_method` -- the report's rule: SciPy's, except that where SciPy would approximate though at most
  :data:`PERMUTATION_AUTO_MAX_N` differences are non-zero (a zero's sign changes no statistic), the permutation
  test enumerates their flips exactly (issue 41: the pooled success test).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = [
    "EXACT_MAX_N",
    "PERMUTATION_AUTO_MAX_N",
    "SCIPY_AUTO_RANGE",
    "auto_method",
    "report_method",
    "sign_flip_distribution",
    "signed_rank_null_counts",
]

#: SciPy's ``auto`` rule: more pairs than this → normal approximation.
EXACT_MAX_N = 50
#: SciPy's ``auto`` rule: with ties or zeros, at most this many pairs → permutation test.
PERMUTATION_AUTO_MAX_N = 13
#: The SciPy releases whose ``auto`` rule :func:`auto_method` states (read in their source); pinned in pyproject.toml.
SCIPY_AUTO_RANGE = ("1.15", "1.17")

# Exact integer counts fit in int64 up to n = 62 (total 2⁶² patterns).
_INT_COUNTS_MAX_N = 62


@functools.lru_cache(maxsize=128)
def _exact_counts(n: int) -> np.ndarray:
    """Number of the 2ⁿ sign patterns giving W⁺ = 0 … n(n+1)/2 (ranks 1…n), int64, n ≤ 62."""
    c = np.zeros(n * (n + 1) // 2 + 1, dtype=np.int64)
    c[0] = 1
    top = 0
    for k in range(1, n + 1):
        # rank k positive or not: c'[w] = c[w] + c[w − k]
        c[k : top + k + 1] += c[: top + 1].copy()
        top += k
    c.flags.writeable = False
    return c


def signed_rank_null_counts(n: int) -> np.ndarray:
    """Exact null distribution of the signed-rank statistic W⁺ for n untied, non-zero differences.

    Parameters
    ----------
    n : int
        Number of ranked differences, 0 ≤ n ≤ 62.

    Returns
    -------
    numpy.ndarray
        ``counts[w]`` = number of the 2ⁿ equally likely sign patterns with
        W⁺ = w, w = 0 … n(n+1)/2 (int64, read-only). P(W⁺ = w) = counts[w] / 2ⁿ.
    """
    if not 0 <= n <= _INT_COUNTS_MAX_N:
        raise ValueError(f"n = {n}: exact integer counts are available for 0 ≤ n ≤ {_INT_COUNTS_MAX_N}")
    return _exact_counts(int(n))


def sign_flip_distribution(units: np.ndarray) -> tuple[np.ndarray, float]:
    """Distribution of Σ s_i·u_i (s_i ∈ {0, 1} fair coins) for non-negative integer ``units``.

    Parameters
    ----------
    units : numpy.ndarray
        Non-negative integers (doubled mid-ranks, so that halves are whole).

    Returns
    -------
    weights, total
        P(S = s) = weights[s] / total. Integer and exact while 2ⁿ fits int64;
        beyond, probabilities in float64 (total = 1).
    """
    size = int(units.sum()) + 1
    exact = units.size <= _INT_COUNTS_MAX_N
    w: npt.NDArray[Any] = np.zeros(size, dtype=np.int64 if exact else np.float64)  # its dtype is chosen at run time
    w[0] = 1
    top = 0
    for u in units.tolist():
        if exact:
            w[u : top + u + 1] += w[: top + 1].copy()
        else:
            prev = w[: top + 1].copy()
            w[: top + 1] *= 0.5
            w[u : top + u + 1] += 0.5 * prev
        top += u
    return w, (float(2**units.size) if exact else 1.0)


def auto_method(n_total: int, n_zero: int, n_ties: int) -> str:
    """The method SciPy's ``wilcoxon(method="auto")`` uses (SciPy 1.15 – 1.17; module docstring).

    Parameters
    ----------
    n_total : int
        Pairs tested, zero differences included.
    n_zero : int
        Zero differences.
    n_ties : int
        Groups of equal non-zero ``|d|`` of size > 1.

    Returns
    -------
    str
        ``"exact"``, ``"permutation"`` or ``"approx"`` (SciPy's ``"asymptotic"``).
    """
    if n_total > EXACT_MAX_N:
        return "approx"
    if n_ties == 0 and n_zero == 0:
        return "exact"
    if n_total <= PERMUTATION_AUTO_MAX_N:
        return "permutation"
    return "approx"


def report_method(n_total: int, n_zero: int, n_ties: int) -> str:
    """The method the report's ``"auto"`` uses: :func:`auto_method`'s, but the exact permutation test wherever
    SciPy would approximate and at most :data:`PERMUTATION_AUTO_MAX_N` differences are non-zero (module docstring).
    """
    used = auto_method(n_total, n_zero, n_ties)
    if used == "approx" and n_total - n_zero <= PERMUTATION_AUTO_MAX_N:
        return "permutation"
    return used
