"""Holm's correction across a family of tests, and the tidy table of a family's results.

:func:`holm` adjusts the p-values of one family (or of many at once, a family per slice: the resampled studies of
the power analysis); :func:`results_frame` tabulates Wilcoxon results (:mod:`analysis.stats.wilcoxon`) with the
Holm-adjusted p of the family they belong to (the report's primary measures; a secondary measure keeps its own).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import asdict, fields

import numpy as np
import numpy.typing as npt
import pandas as pd

from analysis.stats.wilcoxon import WilcoxonResult

__all__ = ["RESULT_COLUMNS", "holm", "results_frame"]


def holm(p_values: npt.ArrayLike, *, axis: int | None = None) -> np.ndarray:
    """Holm (1979) step-down adjusted p-values.

    Parameters
    ----------
    p_values : array_like
        p-values in [0, 1]; NaN entries (untested metrics) stay NaN and do not
        count towards the family size m.
    axis : int or None
        None (default): the whole array is one family.  An axis: every slice
        along it is a family of its own, all adjusted at once (e.g. the four
        metrics of each of thousands of resampled studies, ``axis=-1``).

    Returns
    -------
    numpy.ndarray
        Same shape. With the m finite p-values of a family sorted, p₍₁₎ ≤ … ≤ p₍ₘ₎,
        ``p̃₍ᵢ₎ = min(1, max_{j ≤ i} (m − j + 1)·p₍ⱼ₎)`` — monotone in p and capped
        at 1, as ``statsmodels.stats.multitest.multipletests(method="holm")``.

    Raises
    ------
    ValueError
        If a p-value is outside [0, 1] or infinite.
    """
    p = np.asarray(p_values, dtype=np.float64)
    flat = p.ravel()
    ok = ~np.isnan(flat)
    bad = ok & ~((flat >= 0.0) & (flat <= 1.0))
    if bad.any():
        i = int(np.nonzero(bad)[0][0])
        raise ValueError(f"p_values[{i}] = {flat[i]}: p-values must lie in [0, 1] (or be NaN)")
    if axis is None:
        return _holm_rows(flat.reshape(1, -1)).reshape(p.shape)
    moved = np.moveaxis(p, axis, -1)
    rows = _holm_rows(moved.reshape(-1, moved.shape[-1]))
    return np.moveaxis(rows.reshape(moved.shape), -1, axis)


def _holm_rows(q: np.ndarray) -> np.ndarray:
    """Holm's adjustment of every row of a 2-D array, each row a family (NaN: not in the family)."""
    missing = np.isnan(q)
    m = (~missing).sum(axis=1, keepdims=True)
    # NaN sorts last, so the first m sorted entries of a row are its family, in ascending order
    order = np.argsort(np.where(missing, np.inf, q), axis=1, kind="stable")
    ranked = np.take_along_axis(q, order, axis=1)
    with np.errstate(invalid="ignore"):
        adj = np.minimum(1.0, np.maximum.accumulate((m - np.arange(q.shape[1])) * ranked, axis=1))
    out = np.empty_like(q)
    np.put_along_axis(out, order, adj, axis=1)
    out[missing] = np.nan
    return out



#: Column order of :func:`results_frame`.
RESULT_COLUMNS: tuple[str, ...] = (*tuple(f.name for f in fields(WilcoxonResult)), "p_holm")


def results_frame(results: Sequence[WilcoxonResult], family: Collection[str] | None = None) -> pd.DataFrame:
    """One tidy row per metric with every field of :class:`WilcoxonResult` plus ``p_holm``.

    Parameters
    ----------
    results : sequence of WilcoxonResult
        One test per metric.
    family : collection of str, optional
        The metrics Holm's correction runs across (default: every one of ``results``); a metric outside it keeps
        its own p-value and has no ``p_holm`` (NaN).

    Returns
    -------
    pandas.DataFrame
        Columns are the snake_case field names in declaration order, then
        ``p_holm``: Holm-adjusted p across the *computable* rows of the family
        (a non-computable row has NaN and does not count in m).
    """
    rows = [asdict(r) for r in results]
    frame = pd.DataFrame(rows, columns=list(RESULT_COLUMNS[:-1]))
    p = frame["p_value"].to_numpy(dtype=np.float64)
    counted = frame["computable"].to_numpy(dtype=bool)
    if family is not None:
        counted = counted & frame["metric"].isin(list(family)).to_numpy(dtype=bool)
    p = np.where(counted, p, np.nan)
    frame["p_holm"] = holm(p)
    return frame
