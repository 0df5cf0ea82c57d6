"""The study report: one self-contained HTML page, tidy CSV tables and the figures.

:func:`build_report` reads one or more study databases, recomputes every
trial's metrics from its samples, aggregates per participant and mode, tests
ON vs OFF, draws the paper's figures and writes::

    DIR/report.html            figures embedded, tables, methods paragraph
    DIR/trials.csv             one row per analysed trial
    DIR/participants.csv       per participant × haptic mode
    DIR/participants_wide.csv  one row per participant: OFF and ON columns per measure (JASP, SPSS)
    DIR/participants_by_target.csv
    DIR/stats.csv              one row per metric (paired Wilcoxon ON vs OFF, Holm across metrics)
    DIR/stats_by_target.csv    the same within each target
    DIR/speed_accuracy.csv     speed against accuracy (r_rm) per mode, every reading
    DIR/time_to_event.csv, kaplan_meier.csv, survival_model.csv   TCT as a time to event
    DIR/sessions.csv           every session read, with what was excluded
    DIR/codebook.csv           every column of every CSV: meaning, unit, type
    DIR/figures/*.png, *.pdf, *.svg

The report is built in a temporary folder beside ``DIR`` and moved into place
at the end, so a failed run never leaves half a report or touches an old one;
``--force`` replaces only a report's own, unedited files (the folder policy
of :mod:`foundation.outdir`, shared with ``power``).
"""

from __future__ import annotations

import dataclasses
import functools
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from analysis.plots import figures, model_figures
from analysis.reading.annotations import read_annotations
from analysis.reading.errors import AnalysisError
from analysis.reading.load import Progress, StudyData, load_study
from analysis.reading.metrics import MetricOptions, TrialTable, compute_trials
from analysis.report import report_tables
from analysis.report.annotations_report import (
    annotate,
    annotations_html,
    covariate_codebook,
    noted_deviations,
    questionnaire_results,
)
from analysis.report.groups_report import group_analysis, group_tables, groups_html
from analysis.report.measures import figure_groups, secondary_note, windowed_words
from analysis.report.power_section import power_html
from analysis.report.report_html import page, plural
from analysis.report.study_record import (
    aborted_reruns,
    condition_warnings,
    damaged_trials,
    deviations,
    incomplete_sessions,
    provenance,
    resumed_sessions,
)
from analysis.report.task_sections import SectionInput, SectionOutput, section_for, sections_page, study_parts
from analysis.report.withdrawals import study_withdrawals, withdrawals_html
from analysis.stats.aggregate import PRIMARY_METRICS, TESTED_METRICS, mode_tests, per_participant, unbalanced_cells
from analysis.stats.learning import first_modes, learning_curve, learning_models, order_check
from analysis.stats.models import MIN_PARTICIPANTS, ModelFit
from analysis.stats.sensitivity import max_ae_from_approach, sensitivity
from analysis.stats.sites import site_differences, site_tests, sites_in
from analysis.stats.survival import CoxFit, cox_model, kaplan_meier, time_to_event_summary
from analysis.stats.trade import (
    DEFAULT_READING,
    participant_slopes,
    rm_caption,
    tct_column,
    trade_model,
    trade_pairs,
    trade_readings,
)
from analysis.stats.wilcoxon import WilcoxonResult
from foundation.outdir import REPORT_MARKER, check_output_folder, write_output_folder
from foundation.parallel import default_workers, run_tasks
from protocol.metrics import Role
from protocol.tasks.base import TrialTarget

__all__ = [
    "ReportSummary",
    "build_report",
]


@dataclass(frozen=True, slots=True)
class ReportSummary:
    """What :func:`build_report` wrote and found."""

    out_dir: Path
    n_participants: int
    n_trials: int
    n_samples: int
    excluded: dict[str, int]
    stats: pd.DataFrame
    files: list[str] = field(default_factory=list)
    #: One line per run of damaged recorded blocks (:attr:`analysis.reading.load.StudyData.damage`); the trials they
    #: touch are left out of the analysis and listed in the report.
    damage: tuple[str, ...] = ()
    #: Conditions the analysed sessions did not share (:func:`analysis.report.study_record.condition_warnings`).
    conditions: tuple[str, ...] = ()
    #: What the tasks' sections say for the command line (:attr:`analysis.report.task_sections.SectionOutput.lines`).
    lines: tuple[str, ...] = ()
    #: Each participant's value per haptic mode (participants.csv's table; None for a task without trial metrics):
    #: a study with visits draws its learning curves from each visit's (:mod:`analysis.report.learning_report`).
    overall: pd.DataFrame | None = None


def _example_trials(trials: pd.DataFrame) -> list[pd.Series]:
    """One trial per mode for the pipeline figure: the first participant's first success (else first trial)."""
    first = sorted(trials["participant_code"].unique())[0]
    mine = trials[trials["participant_code"] == first]
    picks = []
    for mode in ("on", "off"):
        sel = mine[mine["haptic_mode"] == mode]
        if sel.empty:
            continue
        ok = sel[sel["outcome"] == "success"]
        picks.append((ok if not ok.empty else sel).iloc[0])
    return picks


def _marks(results: Sequence[WilcoxonResult], frame: pd.DataFrame) -> dict[str, str]:
    """Each test's mark: from Holm's p for a primary measure, from its own p for a secondary one."""
    holm = dict(zip(frame["metric"], frame["p_holm"], strict=True))
    return {r.metric: figures.significance_mark(r, p_holm=holm.get(r.metric) if r.metric in PRIMARY_METRICS else None)
            for r in results}


@dataclass(frozen=True, slots=True)
class _Analysis:
    """Everything the report computes from the study, before any table or page is made."""

    study: StudyData
    table: TrialTable
    trials: pd.DataFrame
    overall: pd.DataFrame
    by_target: pd.DataFrame
    results: list[WilcoxonResult]
    stats: pd.DataFrame
    target_order: list[str]
    target_results: dict[str, list[WilcoxonResult]]
    stats_by_target: pd.DataFrame
    excluded: dict[str, int]
    n_incomplete: int
    n_participants: int
    within: _Within
    confidence: float = 0.95


@dataclass(frozen=True, slots=True)
class _Within:
    """The within-participant analyses: the trade, the error-window sensitivity, learning and order, the record."""

    sa: pd.DataFrame
    trade: pd.DataFrame
    trade_fit: ModelFit | None
    slopes: pd.DataFrame
    sensitivity: pd.DataFrame
    max_ae_approach: tuple[int, int]
    learning: list[ModelFit]
    order: pd.DataFrame
    curve: pd.DataFrame
    incomplete: pd.DataFrame
    deviations: pd.DataFrame
    provenance: pd.DataFrame
    provenance_warnings: list[str]
    reruns: tuple[int, int]
    damaged: pd.DataFrame
    resumed: pd.DataFrame
    km: pd.DataFrame
    tte: pd.DataFrame
    cox: CoxFit
    unbalanced: pd.DataFrame
    site_stats: pd.DataFrame
    site_diff: pd.DataFrame


def _excluded(study: StudyData) -> dict[str, int]:
    """What the analysis leaves out, counted: sessions and trials, by why."""
    all_t = study.trials
    return {
        "training_sessions": int((study.sessions["kind"] != "experiment").sum()),
        "training_trials": int((all_t["excluded"] == "training session").sum()),
        "incomplete_sessions": int(((study.sessions["kind"] == "experiment") & ~study.sessions["analysed"]).sum()),
        "incomplete_trials": int(((all_t["excluded"] == "incomplete session") & (all_t["outcome"] != "aborted")).sum()),
        "aborted_trials": int((all_t["excluded"] == "aborted trial").sum()),
        "damaged_trials": int((all_t["excluded"] == "recording damaged").sum()),
    }


def _analyse(study: StudyData, options: MetricOptions, zero_method: str, confidence: float,
             progress: Progress | None, workers: int | None) -> _Analysis:
    """Recompute every trial of the study, aggregate per participant and test ON vs OFF (overall, per target)."""
    table = compute_trials(study, options, progress=progress, workers=workers)
    trials = table.trials
    overall = per_participant(trials, options)
    by_target = per_participant(trials, options, by_target=True)
    results, stats = mode_tests(overall, zero_method=zero_method, confidence=confidence)
    target_order = list(trials.drop_duplicates("target_label").sort_values("target_force_n")["target_label"])
    per_target: list[pd.DataFrame] = []
    target_results: dict[str, list[WilcoxonResult]] = {}
    for label in target_order:
        res, frame = mode_tests(by_target[by_target["target_label"] == label], zero_method=zero_method,
                                confidence=confidence)
        frame.insert(0, "target_label", label)
        per_target.append(frame)
        target_results[label] = res
    exp = study.sessions[study.sessions["kind"] == "experiment"]
    within = _within(study, table, overall, target_order, options, zero_method, confidence)
    return _Analysis(study, table, trials, overall, by_target, results, stats, target_order, target_results,
                     pd.concat(per_target, ignore_index=True), _excluded(study),
                     int((exp["status"] != "completed").sum()), int(trials["participant_code"].nunique()), within,
                     confidence)


def _within(study: StudyData, table: TrialTable, overall: pd.DataFrame, target_order: list[str],
            options: MetricOptions, zero_method: str, confidence: float) -> _Within:
    """The trade, the sensitivity to the error window, learning and order, and the study record's lists.

    The models are not fitted here (``trade_fit`` None, ``learning`` empty): :func:`_draw` fits them in a worker
    while the figures are drawn (:func:`_fit_models`), each once.
    """
    trials = table.trials
    prov, warn = provenance(study)
    warn = condition_warnings(study) + warn  # pooled conditions first: they qualify every test
    trade = trade_readings(table, confidence=confidence)
    cox = cox_model(trials, target_order, confidence)
    km = kaplan_meier(trials, confidence)
    several = len(sites_in(trials)) > 1
    return _Within(
        sa=trade[trade["reading"] == DEFAULT_READING.key].reset_index(drop=True), trade=trade,
        trade_fit=None,
        slopes=participant_slopes(trials),
        sensitivity=sensitivity(table, options, trade, cox, zero_method=zero_method, confidence=confidence),
        max_ae_approach=max_ae_from_approach(table),
        learning=[],
        order=order_check(overall, first_modes(study.sessions)),
        curve=learning_curve(trials, tct_column(options)),
        incomplete=incomplete_sessions(study), deviations=deviations(study), provenance=prov,
        provenance_warnings=warn, reruns=aborted_reruns(study), damaged=damaged_trials(study),
        resumed=resumed_sessions(study), km=km, tte=time_to_event_summary(trials, km), cox=cox,
        unbalanced=unbalanced_cells(trials),
        site_stats=site_tests(overall, trials, zero_method=zero_method, confidence=confidence) if several
        else pd.DataFrame(),
        site_diff=site_differences(overall, trials) if several else pd.DataFrame(),
    )


def _all_marks(a: _Analysis) -> tuple[dict[str, str], dict[tuple[str, str], str]]:
    """Significance marks per metric overall, and per (metric, scope) for the figures with targets."""
    marks_overall = _marks(a.results, a.stats)
    marks: dict[tuple[str, str], str] = {(m, "overall"): s for m, s in marks_overall.items()}
    for label in a.target_order:
        frame = a.stats_by_target[a.stats_by_target["target_label"] == label]
        for m, s in _marks(a.target_results[label], frame).items():
            marks[(m, label)] = s
    return marks_overall, marks


def _notes(a: _Analysis, options: MetricOptions) -> dict[str, str]:
    """The caveats printed on the figures they qualify."""
    window = ("from the cue, the approach from 0 N included" if options.error_window == "cue" else
              "from first contact")
    no_tct = (int(a.overall.groupby("participant_code")["tct_s"].apply(lambda v: v.isna().any()).sum())
              if "tct_s" in a.overall.columns else 0)  # (a study whose tasks have no TCT: none)
    tct = ("TCT over successful trials only, conditioned on success" + (
        f"; {plural(no_tct, 'participant')} without a success in a mode have no TCT there" if no_tct else "")
           if options.tct_policy == "successful" else
           "TCT over every trial, a failure counted at the trial cap (the paper's figure); over successful trials "
           "only and as a time to event: see Task completion time")
    learning = ("Descriptive; the trial-number effects at fixed mode and target are the models' (report table)."
                if a.n_participants >= MIN_PARTICIPANTS else
                f"Descriptive only: {plural(a.n_participants, 'participant')}, too few for the learning models "
                f"(at least {MIN_PARTICIPANTS}).")
    metrics = a.study.metrics
    notes = {"tct": tct + ".", "errors": f"{windowed_words(metrics)}: error window {window}.",
             "trade": "Every trial that reached the band, failed or not: rise time from first contact to the band, "
                      "RMSE over the 1 s after; lines: each participant's own least-squares fit.",
             "learning": learning}
    for group in figure_groups(metrics):  # a figure with a secondary measure says whose marks are not Holm's
        if any(m.role is Role.SECONDARY for m in group.metrics):
            notes[group.key] = " ".join(filter(None, (notes.get(group.key, ""), secondary_note(metrics))))
    return notes


def _fit_models(trials: pd.DataFrame, target_order: list[str], options: MetricOptions,
                confidence: float) -> tuple[ModelFit, list[ModelFit]]:
    """Every model of the report, each fitted once: the trade's mixed model and one learning model per outcome."""
    return (trade_model(trials, confidence=confidence),
            learning_models(trials, target_order, tct_column(options), confidence))


def _work(kind: str, args: tuple[Any, ...], kwargs: dict[str, Any], folder: str, name: str) -> Any:
    """One task of the report's worker pool: draw a figure (``kind`` is its builder, in :mod:`analysis.plots.figures` or
    :mod:`analysis.plots.model_figures`) or fit the models."""
    if kind == "models":
        return _fit_models(*args)
    if kind in ("trade_slopes", "learning_curves", "km_curves"):
        return figures.save(getattr(model_figures, kind)(*args, **kwargs), folder, name)
    return figures.render(kind, args, kwargs, folder, name)


def _draw(a: _Analysis, options: MetricOptions, marks_overall: dict[str, str], marks: dict[tuple[str, str], str],
          fig_dir: Path, workers: int | None,
          ) -> tuple[dict[str, bytes], list[tuple[str, bytes]], tuple[ModelFit, list[ModelFit]]]:
    """Draw the figures into ``fig_dir`` and fit the models, in parallel: the PNGs by key, the example trials
    with titles, and the fitted models (the trade's, the learning ones)."""
    overall, by_target, trials = a.overall, a.by_target, a.trials
    notes = _notes(a, options)
    common = {str(r.haptic_mode): (float(r.slope_s_per_n), rm_caption(r)) for r in a.within.sa.itertuples()}
    bars = dict(target_order=a.target_order)
    tasks: list[tuple[str, tuple[Any, ...], dict[str, Any], str, str]] = [
        ("models", (trials, a.target_order, options, a.confidence), {}, "", "models"),  # the longest task first
        *(("mode_bars", ([m.participant for m in g.metrics], overall, by_target, marks),
           {**bars, **({"note": notes[g.key]} if g.key in notes else {})}, g.file, g.key)
          for g in figure_groups(a.study.metrics)),
        ("paired_lines", (overall, [m for m in TESTED_METRICS if m in overall.columns], marks_overall), {}, "paired",
         "paired"),
        ("trade_slopes", (trade_pairs(trials), a.within.slopes, common, DEFAULT_READING.speed_label,
                          DEFAULT_READING.accuracy_label),
         {"note": notes["trade"]}, "speed_accuracy", "speed_accuracy"),
        *((("km_curves", (a.within.km, a.within.tte, a.within.cox), {}, "tct_survival", "tct_survival"),)
          if any(m.success_only for m in a.study.metrics) else ()),  # (a task with a TCT: its time to event)
        ("learning_curves", (a.within.curve,), {"note": notes["learning"]}, "learning", "learning"),
    ]
    titles = []
    for ex in _example_trials(trials):
        number = int(ex["trial_index"]) + 1  # trials are numbered from 1 for people (see analysis.reading.codebook)
        code = str(ex["participant_code"]).replace(":", "-")  # a site's code, A:P01, in a file name
        name = f"pipeline_{code}_s{int(ex['session_id'])}_trial{number}"
        title = (f"{ex['participant_code']}, session {int(ex['session_id'])}, trial {number}: {ex['target_label']} "
                 f"{ex['target_force_n']:g} N, haptics {str(ex['haptic_mode']).upper()}, {ex['outcome']}")
        band = a.study.task_of(ex["database"], ex["session_id"]).screen(TrialTarget.of(ex))
        tasks.append(("trial_trace", (str(ex["database"]), int(ex["session_id"]), int(ex["trial_index"])),
                      dict(target_force_n=float(ex["target_force_n"]), band=band, title=title,
                           error_window=options.error_window), name, name))
        titles.append((name, title))
    drawn = run_tasks(_work, [(b, args, k, str(fig_dir), f) for b, args, k, f, _ in tasks],
                      workers=default_workers() if workers is None else workers)
    out = {key: result for (_, _, _, _, key), result in zip(tasks, drawn, strict=True)}
    models = out.pop("models")
    return out, [(title, out[name]) for name, title in titles], models


def _write(tmp: Path, *, a: _Analysis, databases: Sequence[str | os.PathLike[str]], options: MetricOptions,
           zero_method: str, confidence: float, power: bool, workers: int | None,
           results: dict[str, pd.DataFrame], outputs: list[SectionOutput]) -> None:
    """The report's files, written into the folder ``tmp`` (the output policy's temporary folder): the figures, the
    CSVs with their codebook (and ``power.csv``) and report.html; the CSVs' tables as written into ``results``."""
    marks_overall, marks = _all_marks(a)
    pngs, examples, (trade_fit, learning) = _draw(a, options, marks_overall, marks, tmp / "figures", workers)
    # who the participants are, what they answered, what the experimenter noted (nothing, in the paper's study)
    ann = read_annotations(databases)
    answered = questionnaire_results(ann, a.trials)
    within = dataclasses.replace(a.within, trade_fit=trade_fit, learning=learning,
                                 deviations=noted_deviations(ann, a.within.deviations))
    # the files' tables, rounded; the page's, unrounded: it rounds each number once, as it shows it
    tables, shown = (annotate(report_tables.export_tables(a.study, a.trials, a.overall, a.by_target, a.stats,
                                                          a.stats_by_target, within, options.error_window, rounded=r),
                              ann, answered, rounded=r)
                     for r in (True, False))
    grouped = group_analysis(ann, a.trials, a.overall, a.target_order, options, zero_method, confidence)
    tables.update(group_tables(grouped))  # (no [groups] in the protocol: nothing)
    section = withdrawals_html(study_withdrawals(databases), a.study)  # "" when nobody withdrew
    section += annotations_html(ann, answered, dict.fromkeys(a.trials["participant_code"])) + groups_html(grouped)
    if power:
        from analysis.planning.power_outputs import report_section

        section += power_html(report_section(a.trials, options, zero_method, tmp), a.study.metrics)
    written_too = [p.name for p in tmp.glob("*.csv")]  # (power.csv; a section's own CSVs have their own codebook)
    capped = a.trials.assign(max_trial_s=a.study.included["max_trial_s"].to_numpy(dtype=float))
    parts = _sections(a.study, tmp, zero_method, confidence, trials=capped, stats=shown["stats.csv"])
    for part in parts:
        tables.update(part.tables)
    report_tables.write_tables(tmp, tables, written_too=written_too,
                               metrics=a.study.metrics, described=covariate_codebook(ann.declared))
    html = page(
        study=a.study, table=a.table, options=options, zero_method=zero_method, confidence=confidence,
        excluded=a.excluded, n_participants=a.n_participants, n_incomplete=a.n_incomplete, tables=shown,
        marks_overall=marks_overall, pngs=pngs, examples=examples, power_html=section, within=within,
        target_order=a.target_order, sections_html="\n".join(p.html() for p in parts if p.body),
    )
    (tmp / "report.html").write_text(html, encoding="utf-8")
    results.update(tables)
    outputs.extend(parts)


def _sections(study: StudyData, folder: Path, zero_method: str, confidence: float, *,
              trials: pd.DataFrame | None = None, stats: pd.DataFrame | None = None) -> list[SectionOutput]:
    """Each task's section (:mod:`analysis.report.task_sections`), from its own sessions, in the order the tasks first
    appear; ``trials`` (with ``max_trial_s``) and ``stats`` are the core's, where the study has trial metrics."""
    out = []
    for kind, sessions in study_parts(study):
        section = section_for(kind)
        if section is None:
            continue
        keys = set(zip(sessions["database"], sessions["session_id"], strict=True))
        mine = (pd.DataFrame() if trials is None else
                trials[[k in keys for k in zip(trials["database"], trials["session_id"], strict=True)]])
        given = SectionInput(study, kind, sessions, mine, pd.DataFrame() if stats is None else stats, zero_method,
                             confidence)
        out.append(section.build(given, folder))
    return out


def _lines(outputs: Sequence[SectionOutput]) -> tuple[str, ...]:
    """What the sections say for the command line, in order."""
    return tuple(line for o in outputs for line in o.lines)


def _write_sections(tmp: Path, *, study: StudyData, zero_method: str, confidence: float,
                    outputs: list[SectionOutput]) -> None:
    """The report of a study whose tasks have no trial metric: its tasks' sections, each with its files, and a page
    of them (:func:`analysis.report.task_sections.sections_page`)."""
    (tmp / "figures").mkdir()
    parts = _sections(study, tmp, zero_method, confidence)
    if not any(p.body for p in parts):
        kinds = ", ".join(kind for kind, _ in study_parts(study))
        raise AnalysisError(f"{', '.join(study.databases)}: the study's tasks ({kinds}) have no trial metric and "
                            "no report section: nothing to report")
    (tmp / "report.html").write_text(sections_page(parts, study), encoding="utf-8")
    outputs.extend(parts)


def build_report(
    databases: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    *,
    options: MetricOptions = MetricOptions(),
    zero_method: str = "wilcox",
    confidence: float = 0.95,
    force: bool = False,
    progress: Progress | None = None,
    workers: int | None = None,
    power: bool = False,
    include_incomplete: bool = False,
    sites: Sequence[str] | None = None,
    part: str | None = None,
) -> ReportSummary:
    """Analyse one study (one or more databases) and write its report.

    Parameters
    ----------
    databases
        Study databases; they merge into one study.
    out_dir
        Output folder.  It must not exist (or be empty) unless ``force``.
    options
        Error window and TCT policy.
    zero_method, confidence
        Wilcoxon zero handling and the Hodges–Lehmann confidence level.
    force
        Replace an existing, non-empty ``out_dir`` -- only the files ``report`` itself wrote there, unedited (its
        marker lists each with its SHA-256), and only when it holds nothing else: no input database, no file of
        anybody else's (:mod:`foundation.outdir`).
    progress
        ``progress(samples read, samples expected)``.
    workers
        Processes for reading samples and drawing figures (default: the usable cores, at most 4; 1 = none).
    power
        Add "What n would a study need?": the power of the tests against the number of participants, by
        resampling this study's participants (:func:`analysis.planning.power.report_section`; writes ``power.csv``).
    include_incomplete
        Analyse the finished trials of experiment sessions that did not complete (by default they are left
        out; either way the report lists them with the reason).
    sites
        One site per database (``report --site``): codes re-coded ``SITE:CODE``, a site term in the models, the
        tests within each site and each site's seed and protocol in the methods (:func:`load_study`).
    part
        One part of a study of several (:mod:`analysis.report.plan_report`): its sessions only, one task's report.

    Returns
    -------
    ReportSummary

    Raises
    ------
    AnalysisError
        Unreadable input, nothing to analyse, or an existing output folder without ``force``.
    """
    out = check_output_folder(out_dir, command="report", marker=REPORT_MARKER, inputs=databases, force=force)
    study = load_study(databases, include_incomplete=include_incomplete, sites=sites, part=part)
    outputs: list[SectionOutput] = []
    n_samples = int(study.included["n_samples"].fillna(0).sum())
    if not study.metrics:  # (force discrimination's: a fit per participant, no metric per trial) its sections alone
        fill = functools.partial(_write_sections, study=study, zero_method=zero_method, confidence=confidence,
                                 outputs=outputs)
        files = write_output_folder(out, fill, command="report", marker=REPORT_MARKER, inputs=databases, force=force)
        return ReportSummary(out, int(study.included["participant_code"].nunique()), len(study.included), n_samples,
                             _excluded(study), pd.DataFrame(), files, study.damage, (), _lines(outputs))
    a = _analyse(study, options, zero_method, confidence, progress, workers)
    results: dict[str, pd.DataFrame] = {}
    fill = functools.partial(_write, a=a, databases=databases, options=options, zero_method=zero_method,
                             confidence=confidence, power=power, workers=workers, results=results, outputs=outputs)
    files = write_output_folder(out, fill, command="report", marker=REPORT_MARKER, inputs=databases, force=force)
    return ReportSummary(out, a.n_participants, len(a.trials), n_samples, a.excluded, results["stats.csv"], files,
                         a.study.damage, tuple(condition_warnings(a.study)), _lines(outputs))


def fill_report(folder: Path, databases: Sequence[str | os.PathLike[str]], *, part: str,
                options: MetricOptions = MetricOptions(), zero_method: str = "wilcox", confidence: float = 0.95,
                workers: int | None = None, include_incomplete: bool = False) -> ReportSummary:
    """One part's report of a study of several parts (:mod:`analysis.report.plan_report`), written into ``folder``
    (inside the caller's output folder, whose policy writes it): the part's sessions only, its task's core and
    section as :func:`build_report` makes them for a study (a task without trial metrics: its section alone)."""
    study = load_study(databases, include_incomplete=include_incomplete, part=part)
    outputs: list[SectionOutput] = []
    n_samples = int(study.included["n_samples"].fillna(0).sum())
    if not study.metrics:
        _write_sections(folder, study=study, zero_method=zero_method, confidence=confidence, outputs=outputs)
        return ReportSummary(folder, int(study.included["participant_code"].nunique()), len(study.included),
                             n_samples, _excluded(study), pd.DataFrame(), [], study.damage, (), _lines(outputs))
    a = _analyse(study, options, zero_method, confidence, None, workers)
    results: dict[str, pd.DataFrame] = {}
    _write(folder, a=a, databases=databases, options=options, zero_method=zero_method, confidence=confidence,
           power=False, workers=workers, results=results, outputs=outputs)
    return ReportSummary(folder, a.n_participants, len(a.trials), n_samples, a.excluded, results["stats.csv"], [],
                         a.study.damage, tuple(condition_warnings(a.study)), _lines(outputs), a.overall)
