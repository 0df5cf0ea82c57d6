"""What another setting would have changed, measured on a recorded session (the numbers ``replay`` prints).

Pure array arithmetic on what :mod:`pipeline.force.replay` computed and what the
session recorded:

* :func:`trial_differences` -- per trial, the rendered force replayed with
  other settings against the one the participant felt: RMS and peak of the
  difference of their magnitudes, and the delay of the replayed one (the lag
  that best aligns them);
* :func:`filter_trade` -- the moving-average window's trade on the recording
  itself: the noise left at rest and the delay it adds in contact, for a
  range of windows (what ``bench pipeline`` tabulates on synthetic data).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy.signal import correlate

__all__ = ["DEFAULT_WINDOWS", "best_lag_ms", "filter_trade", "moving_average", "trial_differences"]

#: Windows of the filter-trade table (samples; 1 = no filtering).
DEFAULT_WINDOWS = (1, 2, 5, 10, 20, 50)


def moving_average(x: npt.NDArray[np.float64], window: int) -> npt.NDArray[np.float64]:
    """Trailing mean of the last ``window`` samples (fewer at the start), as the pipeline's filter forms it."""
    if window <= 1:
        return np.asarray(x, dtype=np.float64).copy()
    c: npt.NDArray[np.float64] = np.cumsum(np.concatenate(([0.0], np.asarray(x, dtype=np.float64))))
    n = np.arange(1, len(x) + 1)
    lo = np.maximum(0, n - window)
    return (c[n] - c[lo]) / (n - lo)


def best_lag_ms(reference: npt.NDArray[np.float64], delayed: npt.NDArray[np.float64], max_lag: int) -> float:
    """The delay of ``delayed`` behind ``reference`` (1 ms samples), ms: the shift that best correlates their shapes.

    The correlation coefficient (not the difference) is maximised, so a change of
    amplitude -- another f_scale or f_max -- does not pass for a delay; refined
    between samples by a parabola through the three values around the best shift.
    NaN when the signals are too short or too flat to tell, or never correlate
    well (r < 0.5).
    """
    n = len(reference)
    ref = np.asarray(reference, dtype=np.float64)
    dly = np.asarray(delayed, dtype=np.float64)
    if n < 3 * max_lag + 3 or np.ptp(ref) <= 0 or np.ptp(dly) <= 0:
        return math.nan
    core = ref[max_lag : n - max_lag]
    a = core - core.mean()
    na = float(np.sqrt(np.dot(a, a)))
    m = len(a)
    lags = np.arange(-max_lag, max_lag + 1)
    # every shift at once: sum(a * (b - mean b)) = sum(a * b) since a sums to zero, so the numerators are one
    # correlation (FFT); each shifted window's spread comes from running sums (of the signal less its own mean,
    # so the sums do not cancel digits)
    d = dly - dly.mean()
    num = correlate(d, a, mode="valid", method="fft")  # num[j] = sum a[i] * d[j + i], j = k + max_lag
    c1 = np.concatenate(([0.0], np.cumsum(d)))
    c2 = np.concatenate(([0.0], np.cumsum(d * d)))
    shifts = len(lags)
    s1 = c1[m : m + shifts] - c1[:shifts]
    s2 = c2[m : m + shifts] - c2[:shifts]
    var = np.maximum(s2 - s1 * s1 / m, 0.0)
    nb = np.sqrt(var)
    ok = (nb > 1e-12 * max(1.0, float(np.sqrt(np.max(s2))))) & (na > 0)
    r = np.where(ok, num / np.where(ok, na * nb, 1.0), -1.0)
    i = int(np.argmax(r))
    if r[i] < 0.5:
        return math.nan
    if 0 < i < len(lags) - 1:
        y0, y1, y2 = r[i - 1], r[i], r[i + 1]
        den = y0 - 2 * y1 + y2
        return float(lags[i] + (0.5 * (y0 - y2) / den if den < 0 else 0.0))
    return float(lags[i])


def trial_differences(
    trials: pd.DataFrame, recorded: npt.NDArray[np.float64], replayed: npt.NDArray[np.float64],
    ticks: npt.NDArray[np.int64], max_lag_ms: int = 200,
) -> pd.DataFrame:
    """Replayed against recorded rendered force, per trial.

    Parameters
    ----------
    trials
        One row per trial with ``first_tick`` and ``last_tick`` (its records) and whatever should be carried
        over into the result (participant, trial number, mode, outcome).
    recorded, replayed
        Rendered force magnitude of every record, N.
    ticks
        The records' ticks.
    max_lag_ms
        Largest delay searched.

    Returns
    -------
    pandas.DataFrame
        ``trials``' columns and ``rms_difference_N``, ``peak_difference_N``, ``delay_ms``
        (positive: the replayed force lags the recorded one), ``recorded_peak_N``, ``replayed_peak_N``.
    """
    rows = []
    for tr in trials.itertuples(index=False):
        sel = (ticks >= tr.first_tick) & (ticks <= tr.last_tick)
        a, b = recorded[sel], replayed[sel]
        d = b - a
        rows.append({
            "rms_difference_N": float(np.sqrt(np.mean(d * d))) if len(d) else math.nan,
            "peak_difference_N": float(np.max(np.abs(d))) if len(d) else math.nan,
            "delay_ms": best_lag_ms(a, b, max_lag_ms) if len(d) else math.nan,
            "recorded_peak_N": float(np.max(a)) if len(a) else math.nan,
            "replayed_peak_N": float(np.max(b)) if len(b) else math.nan,
        })
    return pd.concat([trials.reset_index(drop=True), pd.DataFrame(rows)], axis=1)


def filter_trade(
    compensated_xyz: npt.NDArray[np.float64], rest: npt.NDArray[np.bool_], contact: npt.NDArray[np.bool_],
    windows: Sequence[int] = DEFAULT_WINDOWS, max_lag_ms: int = 60,
) -> pd.DataFrame:
    """The moving-average window's trade, measured on a recording's compensated force.

    Parameters
    ----------
    compensated_xyz
        The compensated force of every record (n × 3, N): what the filter receives.
    rest
        Records of the tool at rest out of contact (their spread is the noise).
    contact
        Records in contact (where the delay matters).
    windows
        Windows to tabulate, samples.
    max_lag_ms
        Largest delay searched.

    Returns
    -------
    pandas.DataFrame
        ``window``, ``noise_rms_N`` (RMS of the filtered force about the mean of each period at rest, from a
        window after its start), ``delay_ms``
        (lag of the filtered force magnitude behind the unfiltered one in contact; (window − 1)/2 in theory),
        ``group_delay_ms`` (that theory), ``n_rest``, ``n_contact``.
    """
    xyz = np.asarray(compensated_xyz, dtype=np.float64)
    raw_mag = np.linalg.norm(xyz, axis=1)
    out = []
    for w in windows:
        f = np.stack([moving_average(xyz[:, k], w) for k in range(3)], axis=1)
        # the spread about each rest period's own mean, once the window holds rest samples only: neither the
        # bias drifting between pauses nor the filter settling after a contact is noise
        sq, count = 0.0, 0
        for lo, hi in _runs(rest):
            part = f[lo + w : hi]
            if len(part) > 1:
                sq += float(np.sum((part - part.mean(axis=0)) ** 2))
                count += len(part)
        noise = math.sqrt(sq / count) if count else math.nan
        mag = np.linalg.norm(f, axis=1)
        delays = []
        for lo, hi in _runs(contact):
            if hi - lo > 3 * max_lag_ms + 3:
                delays.append(best_lag_ms(raw_mag[lo:hi], mag[lo:hi], max_lag_ms))
        delays = [d for d in delays if math.isfinite(d)]
        out.append({"window": int(w), "noise_rms_N": noise,
                    "delay_ms": float(np.median(delays)) if delays else math.nan,
                    "group_delay_ms": (w - 1) / 2.0, "n_rest": int(rest.sum()), "n_contact": int(contact.sum())})
    return pd.DataFrame(out)


def _runs(mask: npt.NDArray[np.bool_]) -> list[tuple[int, int]]:
    """[start, stop) of every run of True."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist(), strict=True))
