"""The report's CSV tables: exported names and rounding (:mod:`analysis.reading.codebook`), sorted, and the codebook.

:func:`export_tables` turns the computed frames into every CSV as written;
:func:`write_tables` writes them and ``codebook.csv``.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from analysis.reading import codebook
from analysis.reading.load import StudyData
from analysis.report.study_record import session_activity, status_words
from analysis.stats.aggregate import by_mode
from analysis.stats.loop_health import health_summary, health_table
from analysis.stats.models import fixed_effects
from protocol.metrics import METRICS, Metric, primary

__all__ = ["TRIALS_CSV_COLUMNS", "export_tables", "write_tables"]

#: trials.csv: the columns every consumer may rely on, in this order (more follow: the other metrics, in the
#: registry's order).  The primary metrics' are among them (those of the study's: the paper's four for force
#: regulation).  Sorted by participant number, participant code, session and trial.  Names and rounding:
#: :mod:`analysis.reading.codebook`.
TRIALS_CSV_COLUMNS = ("participant_code", "participant_number", "session_id", "trial_number", "target_label",
                      "target_force_N", "haptic_mode", "outcome",
                      *(m.name if m.boolean else m.exported for m in primary(METRICS)), "cue_at_s")


#: The files of TCT as a time to event (the Kaplan-Meier curves and the Cox model).
TIME_TO_EVENT_FILES = ("time_to_event.csv", "kaplan_meier.csv", "survival_model.csv")


def has_time_to_event(trials: pd.DataFrame) -> bool:
    """Whether the study's tasks time their trials to success (a success-only metric: force regulation's TCT); a
    tracking study has none, and no time-to-event analysis to show."""
    return any(m.success_only and m.name in trials.columns for m in METRICS)


def export_tables(study: StudyData, trials: pd.DataFrame, overall: pd.DataFrame, by_target: pd.DataFrame,
                  stats: pd.DataFrame, stats_by_target: pd.DataFrame, within: Any,
                  error_window: str, rounded: bool = True) -> dict[str, pd.DataFrame]:
    """Every CSV of the report as written: exported names, rounded (:func:`analysis.reading.codebook.export`), sorted.

    Parameters
    ----------
    study : StudyData
        The study read (its sessions and loop records).
    trials, overall, by_target, stats, stats_by_target : pandas.DataFrame
        The analysed trials, the per-participant tables and the tests.
    within
        The within-participant analyses (``analysis.report.report._Within``): the trade, the sensitivity table,
        learning and order, incomplete sessions, deviations.
    error_window
        The error window of every RMSE and Max AE in the files, named in each (column ``error_window``).
    rounded
        Round each number as its file has it (the default); False: the same tables unrounded, for the page, which
        rounds each number once as it shows it (:func:`analysis.reading.codebook.export`).

    Returns
    -------
    dict of str to pandas.DataFrame
        File name → table, in the order the files are listed.
    """
    exp = functools.partial(codebook.export, rounded=rounded)
    by_participant = _ByParticipant(trials)
    t = trials_csv(by_participant(trials, "session_id", "trial_index"), error_window, rounded)
    uneven = set(zip(within.unbalanced["participant_code"], within.unbalanced["haptic_mode"], strict=True))
    balanced = overall.assign(targets_balanced=[(c, m) not in uneven for c, m in
                                                zip(overall["participant_code"], overall["haptic_mode"], strict=True)])
    per = exp(by_participant(balanced, "haptic_mode"), "participants.csv")
    per_t = exp(by_participant(by_target, "haptic_mode", "target_label"), "participants_by_target.csv")
    wide = _wide(per, overall, by_participant)
    st = exp(stats, "stats.csv")
    st_t = exp(stats_by_target, "stats_by_target.csv")
    sess = study.sessions.drop(columns=["clock"], errors="ignore")  # (the page says what the clock means)
    sess = sess.merge(session_activity(study), on=["database", "session_id"], how="left")
    sess["status"] = [status_words(st_, w) for st_, w in zip(sess["status"], sess["writer"], strict=True)]
    sess["database"] = sess["database"].map(os.path.basename)
    health = health_table(study)
    health["database"] = health["database"].map(os.path.basename)
    tables = {
        "trials.csv": t,
        "participants.csv": per,
        "participants_wide.csv": exp(wide, "participants_wide.csv"),
        "participants_by_target.csv": per_t,
        "stats.csv": st,
        "stats_by_target.csv": st_t,
        "sensitivity.csv": exp(within.sensitivity.assign(
            measure=within.sensitivity["measure"].map(codebook.exported_name)), "sensitivity.csv"),
        "speed_accuracy.csv": exp(within.trade, "speed_accuracy.csv"),
        "speed_accuracy_model.csv": exp(fixed_effects([within.trade_fit]), "speed_accuracy_model.csv"),
        "speed_accuracy_slopes.csv": exp(by_participant(within.slopes, "haptic_mode"),
                                                     "speed_accuracy_slopes.csv"),
        "learning_models.csv": exp(fixed_effects(within.learning), "learning_models.csv"),
        "order_check.csv": exp(within.order, "order_check.csv"),
        "time_to_event.csv": exp(within.tte, "time_to_event.csv"),
        "kaplan_meier.csv": exp(within.km, "kaplan_meier.csv"),
        "survival_model.csv": exp(within.cox.table(), "survival_model.csv"),
        "sessions.csv": exp(sess, "sessions.csv"),
        "incomplete_sessions.csv": exp(within.incomplete, "incomplete_sessions.csv"),
        "deviations.csv": exp(within.deviations, "deviations.csv"),
        "loop_health.csv": exp(by_participant(health, "session_id", "trial_index"), "loop_health.csv"),
        "loop_health_by_participant.csv": exp(by_participant(health_summary(health)),
                                                          "loop_health_by_participant.csv"),
    }
    if not has_time_to_event(trials):  # a task without a completion time (tracking): no empty files claiming one
        for name in TIME_TO_EVENT_FILES:
            del tables[name]
    if len(within.site_stats):  # sites named: the tests within each site, and the sites compared
        tables["stats_by_site.csv"] = exp(within.site_stats, "stats_by_site.csv")
        tables["site_differences.csv"] = exp(within.site_diff, "site_differences.csv")
    for name in _WINDOWED_FILES:  # every table with an RMSE or Max AE names the window it was taken over
        if name in tables:
            tables[name]["error_window"] = error_window
    return tables


class _ByParticipant:
    """Sorts a table's rows by participant number, then code (then the keys given), adding the number if missing."""

    def __init__(self, trials: pd.DataFrame) -> None:
        self.numbers = dict(zip(trials["participant_code"], trials["participant_number"], strict=True))
        order = sorted(self.numbers, key=lambda code: (self.numbers[code], code))
        self.rank = {code: i for i, code in enumerate(order)}

    def __call__(self, frame: pd.DataFrame, *keys: str) -> pd.DataFrame:
        out = frame.copy()
        if "participant_number" not in out.columns:
            out.insert(1, "participant_number", out["participant_code"].map(self.numbers).astype(np.int64))
        out["_rank"] = out["participant_code"].map(self.rank)
        return out.sort_values(["_rank", *keys], kind="stable").drop(columns="_rank").reset_index(drop=True)


def _wide(per: pd.DataFrame, overall: pd.DataFrame, by_participant: _ByParticipant) -> pd.DataFrame:
    """participants_wide.csv's rows (before export): each measure of participants.csv as an OFF and an ON column, and
    each tested measure's ON − OFF difference as the test ranks it (from the unrounded values, rounded to
    :data:`analysis.reading.codebook.DIFFERENCE_DECIMALS`)."""
    measures = [m for m in codebook.WIDE_MEASURES if m in per.columns]  # the study's
    wide = per.pivot(index=["participant_code", "participant_number"], columns="haptic_mode", values=measures)
    wide.columns = [codebook.wide_name(measure, mode) for measure, mode in wide.columns]
    wide_cols = [codebook.wide_name(measure, mode) for measure in measures for mode in ("off", "on")]
    wide = by_participant(wide.reindex(columns=wide_cols).reset_index())
    for c in wide_cols:
        if c.startswith("n_"):
            wide[c] = wide[c].astype("Int64")  # a participant without trials in a mode: empty, not 0.0
    sources = {codebook.exported_name(c): c for c in overall.columns}
    for name in (n for n in codebook.DIFF_MEASURES if n in sources):  # the study's tested measures
        source = sources[name]
        both = by_mode(overall, source)
        diff = np.round(both["on"] - both["off"], codebook.DIFFERENCE_DECIMALS)
        wide[codebook.wide_name(name, "diff")] = wide["participant_code"].map(diff).to_numpy(float)
    return wide


def trials_csv(trials: pd.DataFrame, error_window: str, rounded: bool = True) -> pd.DataFrame:
    """The rows of ``trials.csv`` for these trials, in their order: exported names, the database's file name,
    the columns every consumer relies on first, and the error window their RMSE and Max AE were taken over."""
    t = trials.copy()
    t["database"] = t["database"].map(os.path.basename)
    t = codebook.export(t, "trials.csv", rounded=rounded)
    first = [c for c in TRIALS_CSV_COLUMNS if c in t.columns]  # (a study's metrics: its tasks')
    t = t[first + [c for c in t.columns if c not in first]]
    t["error_window"] = error_window
    return t.reset_index(drop=True)


#: The files whose numbers depend on the error window (sensitivity.csv names it per row).
_WINDOWED_FILES = ("participants.csv", "participants_wide.csv", "participants_by_target.csv",
                   "stats.csv", "stats_by_target.csv", "stats_by_site.csv", "site_differences.csv",
                   "learning_models.csv", "order_check.csv")


def write_tables(folder: Path, tables: dict[str, pd.DataFrame], written_too: Sequence[str] = (),
                 metrics: Sequence[Metric] | None = None,
                 described: Mapping[tuple[str, str], tuple[str, str, str]] | None = None) -> None:
    """Write the CSVs and ``codebook.csv``, which describes every column of every one (itself included).

    Parameters
    ----------
    folder : pathlib.Path
        Where to write.
    tables : dict of str to pandas.DataFrame
        :func:`export_tables`' result.
    written_too : sequence of str
        CSV files already in ``folder`` (``power.csv``) that the codebook describes as well.
    metrics : sequence of Metric
        The study's metrics, which the codebook's descriptions of the tests name (:func:`codebook.metric_words`).
    described : mapping, optional
        (file, column) → (type, unit, description) of columns the study's own declarations describe (a covariate's
        column in the participants' tables).
    """
    for name, frame in tables.items():
        frame.to_csv(folder / name, index=False)
    columns = {name: list(frame.columns) for name, frame in tables.items()}
    for name in written_too:
        columns[name] = list(pd.read_csv(folder / name, nrows=0).columns)
    columns["codebook.csv"] = ["file", "column", "type", "unit", "description"]
    codebook.codebook_frame(columns, metrics, described).to_csv(folder / "codebook.csv", index=False)

