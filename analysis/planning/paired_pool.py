"""The resampling pool of the power analysis: per-participant OFF and ON values, aggregated as the report does."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from analysis.reading.load import Progress, load_study
from analysis.reading.metrics import MetricOptions, compute_trials
from analysis.stats.aggregate import PRIMARY_METRICS, TESTED_METRICS, by_mode, per_participant

__all__ = ["PairedPool", "load_pool", "pool_from_trials"]


@dataclass(frozen=True, slots=True)
class PairedPool:
    """Per-participant OFF and ON values to resample from.

    Attributes
    ----------
    participants
        Participant codes, in the order of the last axis of ``off`` and ``on``.
    scopes
        ``"overall"``, then the target labels in order of target force.
    metrics
        The metrics the report tests (:data:`analysis.stats.aggregate.TESTED_METRICS`): the primary ones, Holm's
        family (:attr:`family`), then any secondary one.
    off, on
        Shape (scopes, metrics, participants); NaN where a value is undefined
        (TCT with no successful trial in that mode) or a participant lacks a mode.
    source
        Where the values come from, in words (for the outputs).
    options
        The aggregation choices (error window, TCT policy).
    """

    participants: tuple[str, ...]
    scopes: tuple[str, ...]
    metrics: tuple[str, ...]
    off: npt.NDArray[np.float64]
    on: npt.NDArray[np.float64]
    source: str
    options: MetricOptions = MetricOptions()

    @property
    def n_participants(self) -> int:
        """Participants in the pool."""
        return len(self.participants)

    @property
    def family(self) -> npt.NDArray[np.bool_]:
        """Which of :attr:`metrics` are in Holm's family (the primary measures), as the report corrects them."""
        return np.array([m in PRIMARY_METRICS for m in self.metrics], dtype=bool)


def pool_from_trials(trials: pd.DataFrame, options: MetricOptions = MetricOptions(), *, source: str = "") -> PairedPool:
    """The resampling pool of an analysed trial table.

    Parameters
    ----------
    trials
        :attr:`analysis.reading.metrics.TrialTable.trials` (or a table with its columns).
    options
        Error window and TCT policy, as in the report.
    source
        Where the trials come from, in words.

    Returns
    -------
    PairedPool
        Only participants with trials in both haptic modes are kept.
    """
    overall = per_participant(trials, options)
    modes = overall.groupby("participant_code")["haptic_mode"].nunique()
    codes = tuple(sorted(str(c) for c in modes[modes == 2].index))
    by_target = per_participant(trials, options, by_target=True)
    order = trials.drop_duplicates("target_label").sort_values("target_force_n")["target_label"].tolist()
    scopes = ("overall", *[str(t) for t in order])
    metrics = tuple(m for m in TESTED_METRICS if m in overall.columns)
    off = np.full((len(scopes), len(metrics), len(codes)), np.nan)
    on = off.copy()
    for s, scope in enumerate(scopes):
        part = overall if scope == "overall" else by_target[by_target["target_label"] == scope]
        for m, metric in enumerate(metrics):
            wide = by_mode(part, metric, codes)
            off[s, m], on[s, m] = wide["off"].to_numpy(dtype=float), wide["on"].to_numpy(dtype=float)
    return PairedPool(codes, scopes, metrics, off, on, source, options)


def load_pool(
    databases: Sequence[str | os.PathLike[str]],
    options: MetricOptions = MetricOptions(),
    *,
    source: str | None = None,
    progress: Progress | None = None,
    workers: int | None = None,
    participants: Sequence[str] | None = None,
    part: str | None = None,
) -> PairedPool:
    """Read study databases (read-only), recompute every trial as the report does, and build the pool.

    Parameters
    ----------
    databases
        Pilot study databases; they merge into one study, as in the report.
    options
        Error window and TCT policy.
    source
        Description for the outputs (default: the database names).
    progress, workers
        As in :func:`analysis.reading.metrics.compute_trials`.
    participants
        Only these participant codes (the first N of a larger simulated pool); default: all.
    part
        In a study of several parts: that part's sessions only (its task's measures); default: a study of one task.
    """
    study = load_study(databases, part=part)
    if participants is not None:
        import dataclasses

        keep = set(participants)
        study = dataclasses.replace(study, trials=study.trials[study.trials["participant_code"].isin(keep)],
                                    sessions=study.sessions[study.sessions["participant_code"].isin(keep)])
    trials = compute_trials(study, options, progress=progress, workers=workers).trials
    if source is None:
        source = "the pilot study " + ", ".join(os.path.basename(str(d)) for d in databases)
        if part is not None:
            source += f" (its part {part!r})"
    return pool_from_trials(trials, options, source=source)
