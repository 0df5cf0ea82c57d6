"""Per-trial metrics recomputed from the stored samples.

The definition is each session's task's offline form (:meth:`protocol.tasks.base.Task.judge`), the very code the
live trial machine used; analysis adds only the choices the paper leaves open (:class:`MetricOptions`) and a check
that the recomputed numbers equal the ones stored during the session.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from analysis.reading.load import Progress, StudyData, connect_readonly, recorded_where, stored_records
from analysis.reading.recorded import read_task_force
from foundation.parallel import default_workers, run_tasks
from protocol.metrics import Metric, MetricValue, stored, windowed
from protocol.study.records import Outcome, TrialRecord, disagreement
from protocol.tasks.base import Task
from protocol.tasks.window import ERROR_WINDOWS, TrialMetrics

__all__ = ["ERROR_WINDOWS", "TCT_POLICIES", "MetricOptions", "TrialTable", "compute_trials"]

#: How a failed trial enters TCT: left out, or censored at the trial cap (the default, :class:`MetricOptions`).
TCT_POLICIES = ("successful", "censored")

@dataclass(frozen=True, slots=True)
class MetricOptions:
    """The analysis choices the paper leaves open.

    Attributes
    ----------
    error_window
        ``"cue"`` (default): RMSE and Max AE over the whole trial window, from
        the cue to the trial end, approach included (what the participant was
        asked to do from the cue on); ``"first_contact"``: from the first
        sample above :data:`protocol.tasks.window.CONTACT_THRESHOLD_N`.
    tct_policy
        ``"censored"`` (default: the paper's figure's reading, "across all targets and trials"): a failed trial
        counts as the trial cap (12 s), so every trial contributes, slow failures are not rewarded and the mean is
        the restricted mean time to success; ``"successful"`` (the paper's text's definition): TCT is averaged
        over successful trials only, conditioned on success, and undefined for a participant with no success in a
        mode.  The report shows both readings with their n, and TCT as a time to event
        (:mod:`analysis.stats.survival`).
    """

    error_window: str = "cue"
    tct_policy: str = "censored"

    def __post_init__(self) -> None:
        if self.error_window not in ERROR_WINDOWS:
            raise ValueError(f"error_window = {self.error_window!r}: allowed values are {', '.join(ERROR_WINDOWS)}")
        if self.tct_policy not in TCT_POLICIES:
            raise ValueError(f"tct_policy = {self.tct_policy!r}: allowed values are {', '.join(TCT_POLICIES)}")


@dataclass(frozen=True, slots=True)
class TrialTable:
    """The analysed trials and how they were obtained.

    Attributes
    ----------
    trials
        One row per analysed trial: ``participant_code, participant_number,
        session_id, trial_index, started_at_s`` (the cue, session clock),
        ``target_label, target_force_n, haptic_mode, outcome``, every metric of the study (:attr:`metrics`) in
        the registry's order (force regulation's ``success, tct_s, rmse_n, max_ae_n, time_in_band_s,
        peak_force_n``, ...), ``first_contact_s``, each success-only metric censored at the trial cap
        (``tct_censored_s``) and ``database``.  ``tct_s`` is NaN unless the trial succeeded; ``tct_censored_s`` is
        ``tct_s`` or the trial cap.  A metric a trial's task does not produce (a study of several tasks) is NaN.
    n_from_samples
        Trials whose metrics were recomputed from samples.
    n_stored_only
        Trials without samples, whose stored metrics were used.
    n_disagree
        Trials whose recomputed outcome or stored metrics (cue window) differ from the ones stored live (should be
        0; a non-zero count is reported).
    by_window
        The study's window-dependent metrics (:func:`protocol.metrics.windowed`: ``rmse_n``, ``max_ae_n``, ...) of
        every trial in each error window (:data:`ERROR_WINDOWS`), row for row with ``trials``: what the sensitivity
        analysis compares.  A trial without samples has its stored (cue-window) values in the cue window, NaN in
        the other.
    error_window
        The window of ``trials``' own window-dependent metrics.
    metrics
        The study's metrics (:attr:`analysis.reading.load.StudyData.metrics`): the columns of ``trials`` they name.
    """

    trials: pd.DataFrame
    n_from_samples: int
    n_stored_only: int
    n_disagree: int
    by_window: dict[str, pd.DataFrame] = field(default_factory=dict)
    error_window: str = "cue"
    metrics: tuple[Metric, ...] = ()

    def in_window(self, window: str) -> pd.DataFrame:
        """``trials`` with the window-dependent metrics of ``window`` (one of :data:`ERROR_WINDOWS`)."""
        if window == self.error_window or window not in self.by_window:
            return self.trials
        out = self.trials.copy()
        for col, values in self.by_window[window].items():
            out[col] = values.to_numpy()
        return out


@dataclass(frozen=True, slots=True)
class _Check:
    """One analysed trial to recompute: its stored record, its session's task and trial cap, where its samples are."""

    row: int
    stored: TrialRecord
    task: Task
    max_trial_s: float
    where: tuple[int, int, int, int] | None


@dataclass(frozen=True, slots=True)
class _Recomputed:
    """A trial's metrics recomputed in ``window`` (None: it has no samples), in every error window, and whether
    the live ones agree."""

    row: int
    metrics: TrialMetrics | None
    agrees: bool
    by_window: dict[str, TrialMetrics] | None = None


def _nan(v: MetricValue) -> float:
    return math.nan if v is None else float(v)


def _chunk(database: str, checks: list[_Check], window: str) -> list[_Recomputed]:
    """Recompute the metrics of some trials of one database (runs in a worker process)."""
    out: list[_Recomputed] = []
    conn = connect_readonly(database)
    try:
        for c in checks:
            t_ns, force = read_task_force(conn, c.stored.trial_id, c.where)
            if len(t_ns) == 0:
                out.append(_Recomputed(c.row, None, True))
                continue
            # every window, for the report's sensitivity table; the live metrics are the cue window's
            every = {w: c.task.judge(t_ns, force, c.stored, max_trial_s=c.max_trial_s, window=w)
                     for w in ERROR_WINDOWS}
            out.append(_Recomputed(c.row, every[window], not disagreement(every["cue"], c.stored), every))
    finally:
        conn.close()
    return out


def _checks(study: StudyData, inc: pd.DataFrame) -> list[_Check]:
    """What each analysed trial's worker needs, in row order."""
    cap = inc["max_trial_s"].to_numpy(dtype=float)
    tasks = [study.task_of(db, sid) for db, sid in zip(inc["database"], inc["session_id"], strict=True)]
    wheres = [recorded_where(*r) for r in zip(inc["session_id"], inc["segment"], inc["first_tick"], inc["last_tick"],
                                              strict=True)]
    return [_Check(i, rec, tasks[i], cap[i], wheres[i]) for i, rec in enumerate(stored_records(inc))]


def _tasks(inc: pd.DataFrame, checks: list[_Check], workers: int, window: str,
           ) -> tuple[list[tuple[str, list[_Check], str]], list[float], float]:
    """The checks cut into chunks of about an equal number of samples, several per worker so the work evens out.

    Returns the tasks (one database each), each chunk's weight and the total weight (samples read, roughly).
    """
    weights = np.nan_to_num(inc["n_samples"].to_numpy(dtype=float), nan=1.0) + 1.0
    per_chunk = max(1.0, float(weights.sum()) / (4 * workers)) if workers > 1 else float("inf")
    tasks: list[tuple[str, list[_Check], str]] = []
    chunk_weight: list[float] = []
    for db in dict.fromkeys(inc["database"]):
        cur: list[_Check] = []
        w = 0.0
        for i in np.flatnonzero((inc["database"] == db).to_numpy()):
            cur.append(checks[i])
            w += weights[i]
            if w >= per_chunk:
                tasks.append((str(db), cur, window))
                chunk_weight.append(w)
                cur, w = [], 0.0
        if cur:
            tasks.append((str(db), cur, window))
            chunk_weight.append(w)
    return tasks, chunk_weight, float(weights.sum())


def _table(inc: pd.DataFrame, results: list[list[_Recomputed]], options: MetricOptions,
           metrics: tuple[Metric, ...]) -> TrialTable:
    """The analysed trials: recomputed metrics (the study's) where there were samples, the stored ones elsewhere."""
    n = len(inc)
    values = {m.name: np.full(n, np.nan) for m in metrics if not m.boolean}
    first_contact = np.full(n, np.nan)
    success = (inc["outcome"] == Outcome.SUCCESS).to_numpy().copy()
    from_samples = np.zeros(n, dtype=bool)
    disagree = 0
    for chunk in results:
        for r in chunk:
            if r.metrics is not None:
                m = r.metrics
                from_samples[r.row] = True
                success[r.row] = m.success
                for name, column in values.items():  # (a metric its task does not produce: NaN)
                    column[r.row] = _nan(m.values.get(name))
                first_contact[r.row] = _nan(m.first_contact_s)
                disagree += not r.agrees
    # trials without samples keep the metrics stored live (cue window only)
    missing = ~from_samples
    for metric in stored(metrics):
        if options.error_window == "cue" or not metric.windowed:
            values[metric.name][missing] = inc.loc[missing, f"stored_{metric.name}"].to_numpy(dtype=float)
    cap = inc["max_trial_s"].to_numpy(dtype=float)
    out = pd.DataFrame(
        {
            "participant_code": inc["participant_code"],
            "participant_number": inc["participant_number"].astype(np.int64),
            "session_id": inc["session_id"].astype(np.int64),
            "trial_index": inc["trial_index"].astype(np.int64),
            "started_at_s": inc["started_at_s"].to_numpy(dtype=float),
            "target_label": inc["target_label"],
            "target_force_n": inc["target_force_n"].to_numpy(dtype=float),
            "haptic_mode": inc["haptic_mode"],
            "outcome": np.where(success, Outcome.SUCCESS.value, Outcome.TIMEOUT.value),
            # a yes/no metric is the task's verdict; the others by name, in the registry's order
            **{m.name: success if m.boolean else values[m.name] for m in metrics},
            "first_contact_s": first_contact,
            **{m.censored: np.where(success, values[m.name], cap) for m in metrics if m.censored},
            "database": inc["database"],
            # a study pooled from named sites (report --site): each trial's, for the models' site terms and the
            # tables per site; none otherwise, so a one-site study's tables are as they were
            **({"site": inc["site"].astype(str)} if "site" in inc and inc["site"].astype(str).str.len().any()
               else {}),
        }
    )
    return TrialTable(out, int(from_samples.sum()), int(missing.sum()), disagree,
                      _by_window(inc, results, metrics), options.error_window, metrics)


def _by_window(inc: pd.DataFrame, results: list[list[_Recomputed]],
               metrics: tuple[Metric, ...]) -> dict[str, pd.DataFrame]:
    """Every trial's window-dependent metrics in each window (stored cue values where there are no samples)."""
    n = len(inc)
    names = [m.name for m in windowed(metrics)]
    out = {w: np.full((n, len(names)), np.nan) for w in ERROR_WINDOWS}
    out["cue"][:] = inc[[f"stored_{m}" for m in names]].to_numpy(dtype=float)
    for chunk in results:
        for r in chunk:
            if r.by_window is not None:
                for w, m in r.by_window.items():
                    out[w][r.row] = [_nan(m.values.get(name)) for name in names]
    return {w: pd.DataFrame(v, columns=names, index=inc.index) for w, v in out.items()}


def compute_trials(
    study: StudyData,
    options: MetricOptions = MetricOptions(),
    *,
    progress: Progress | None = None,
    workers: int | None = None,
) -> TrialTable:
    """Recompute every analysed trial's metrics from its samples.

    Parameters
    ----------
    study
        From :func:`analysis.reading.load.load_study`.
    options
        Window and TCT choices.
    progress
        ``progress(samples read, samples expected)``.
    workers
        Processes reading samples (default: :func:`foundation.parallel.default_workers`; 1 = in this process).

    Returns
    -------
    TrialTable
    """
    inc = study.included.reset_index(drop=True)
    workers = default_workers() if workers is None else max(1, int(workers))
    tasks, chunk_weight, total = _tasks(inc, _checks(study, inc), workers, options.error_window)
    done = [0.0]

    def tick(i: int, _: object) -> None:
        done[0] += chunk_weight[i]
        if progress is not None:
            progress(min(done[0], total), total)

    if progress is not None:
        progress(0.0, total)
    return _table(inc, run_tasks(_chunk, tasks, workers=workers, on_done=tick), options, study.metrics)
