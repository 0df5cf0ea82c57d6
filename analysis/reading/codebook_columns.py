"""The codebook's entries: what every column of every CSV the report writes means, one table in code.

Each :class:`Column` names a column as it appears in the CSV files, what it means, its unit, its type and how far
it is rounded.  The metrics' own columns -- one trial's value, the per-participant means, rates and counts -- are
made from the metric registry (:mod:`protocol.metrics`), so a metric defined there is described here without an
edit; every other column has its line in :data:`COLUMNS`.  :mod:`analysis.reading.codebook` turns an analysis
table into a file's form with them.  A few descriptions name the study's measures -- the ones tested, Holm's family,
the secondary ones -- which are its tasks' (:attr:`analysis.reading.load.StudyData.metrics`): they hold the
placeholders of :func:`metric_words`, filled in for the study's files (:meth:`Column.described`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from protocol.metrics import METRICS, Metric, Role, exported_name, family_word, tested
from protocol.tasks.base import Parameter
from protocol.tasks.registry import TASKS

__all__ = ["COLUMNS", "STATS_CSV_COLUMNS", "Column", "metric_words", "participant_measures", "task_column"]


@dataclass(frozen=True, slots=True)
class Column:
    """One column of the exported files.

    Attributes
    ----------
    name
        The column's name in the CSV files.
    description
        What it holds, in words.
    unit
        ``"N"``, ``"s"``, ``"count"``, ``"fraction (0–1)"``, ... or ``""`` for text and codes.
    type
        ``"text"``, ``"integer"``, ``"number"`` or ``"boolean"``.
    label
        Short heading for tables in ``report.html`` (default: ``name``).
    files
        The files in which it has this meaning; empty: every file.
    source
        The analysis table's name for it, when the export renames it.
    decimals, significant
        Round to this many decimals, or to this many significant digits (numbers only).
    """

    name: str
    description: str
    unit: str = ""
    type: str = "number"
    label: str = ""
    files: tuple[str, ...] = ()
    source: str = ""
    decimals: int | None = None
    significant: int | None = None

    def described(self, words: Mapping[str, str]) -> str:
        """Its description with the study's measures named (:func:`metric_words`)."""
        text = self.description
        for key, value in words.items():
            text = text.replace(f"{{{key}}}", value)
        return text


_STATS = ("stats.csv", "stats_by_target.csv", "target_speed_test.csv")
#: The tests' files (:data:`_STATS`): the columns every consumer may rely on, first and in this order (more follow).
STATS_CSV_COLUMNS = ("metric", "n", "median_off", "median_on", "statistic", "p_value", "method",
                     "zero_method", "rank_biserial", "p_holm")
_SA = ("speed_accuracy.csv",)
_SLOPES = ("speed_accuracy_slopes.csv",)
_MODELS = ("speed_accuracy_model.csv", "learning_models.csv")
_ORDER = ("order_check.csv",)
_SENS = ("sensitivity.csv",)
_PER = ("participants.csv", "participants_by_target.csv")
_SPEED, _SPEED_SLOPES = ("target_speed.csv",), ("target_speed_slopes.csv",)
_MU = "unit of the measure (see metric)"
#: Force: 0.1 mN, far finer than the F/T sensor resolves in one sample (means over 1 kHz trials resolve more).
_F = 4
#: Time: the 1 ms sample period.
_T = 3

#: The placeholders of the descriptions that name the study's measures (:func:`metric_words`).
_FAMILY, _TESTED, _SECONDARY = "{family}", "{tested}", "{secondary}"


def task_column(p: Parameter) -> Column:
    """A task's parameter as a column of the sessions and trials tables (:attr:`protocol.tasks.base.Task.described`)."""
    return Column(p.name, p.description, p.unit, label=p.label, decimals=p.decimals)


def metric_words(metrics: Sequence[Metric] | None) -> dict[str, str]:
    """What the descriptions say of a study's measures (its ``metrics``): how many Holm's family has, in a word
    (``four``), the ones tested, and what a secondary one's ``p_holm`` is; None: in general words (a heading's
    hover text, made without a study)."""
    if metrics is None:
        return {"family": "primary", "tested": "one of the tested measures",
                "secondary": "; empty for a secondary measure, tested on its own, outside the family"}
    names = [m.participant_exported for m in tested(metrics)]
    secondaries = [m.participant_exported for m in metrics if m.role is Role.SECONDARY]
    return {
        "family": family_word(metrics),
        "tested": names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}" if names else "none",
        "secondary": (f"; empty for a secondary measure ({', '.join(secondaries)}), tested on its own, outside the "
                      "family" if secondaries else ""),
    }


def _source(m: Metric) -> str:
    return m.name if m.exported != m.name else ""


def _trial_metric_columns() -> tuple[Column, ...]:
    """One trial's value of every metric (trials.csv: a study's are its tasks')."""
    return tuple(Column(m.name, m.description, type="boolean") if m.boolean else
                 Column(m.exported, m.description, m.unit, label=m.label, source=_source(m), decimals=m.decimals)
                 for m in METRICS)


def _censored_columns() -> tuple[Column, ...]:
    """A success-only metric with a failed trial counted as the trial cap (trials.csv's ``tct_censored_s``)."""
    return tuple(Column(exported_name(c), f"{m.short}, with a failed trial counted as the trial cap", m.unit,
                        label=f"{m.short} censored ({m.unit})", source=c if exported_name(c) != c else "",
                        decimals=m.decimals)
                 for m in METRICS if (c := m.censored))


def _participant_metric_columns() -> tuple[Column, ...]:
    """Every metric per participant × mode (× target): a rate and its count, a mean (and its count)."""
    out: list[Column] = []
    for m in METRICS:
        if m.boolean:
            out += [Column(str(m.count), m.count_description, "count", "integer", label=m.count_label, files=_PER),
                    Column(m.participant, m.participant_description, "fraction (0–1)", label=m.label, decimals=4)]
            continue
        out.append(Column(m.exported, m.participant_description, m.unit, label=m.label, files=_PER,
                          source=_source(m), decimals=m.decimals))
        if m.success_only:
            out.append(Column(str(m.count), f"trials that entered the {m.short} mean", "count", "integer",
                              label=f"{m.short} trials", files=_PER))
    return tuple(out)


def participant_measures() -> tuple[str, ...]:
    """The per-participant measure columns as the files name them, in order (``n_success, success_rate, tct_s,
    n_tct, rmse_N``, ...; participants.csv has ``n_trials`` before them): every metric's, of which a study's
    participants.csv has its tasks'."""
    out: list[str] = []
    for m in METRICS:
        out += ([str(m.count), m.participant] if m.boolean else
                [m.exported, str(m.count)] if m.success_only else [m.exported])
    return tuple(out)


COLUMNS: tuple[Column, ...] = (
    # -- who and which trial --------------------------------------------------------------------------
    Column("participant_code", "pseudonymous participant code, as entered for the session", type="text",
           label="participant"),
    Column("participant_number", "the participant's number in the study (sets the counterbalanced schedule)",
           type="integer", label="number"),
    Column("session_id", "session in its database (sessions.session_id)", type="integer", label="session"),
    Column("trial_number", "trial within its session, numbered from 1 as the experimenter's window shows it "
           "(the database's trials.trial_index is trial_number − 1)", type="integer", label="trial",
           source="trial_index"),
    Column("database", "file name of the study database the row comes from", type="text"),
    Column("target_label", "target force level (GENTLE or FIRM in the paper's protocol)", type="text",
           label="target"),
    Column("target_force_N", "target force F*", "N", label="target (N)", source="target_force_n", decimals=_F),
    Column("haptic_mode", "haptic feedback during the trial: on or off", type="text", label="haptics"),
    Column("haptic_mode", "haptic feedback of the trials correlated: on, off, or all (both modes, each "
           "participant × mode a group of its own)", type="text", label="haptics", files=_SA),
    # -- one trial ----------------------------------------------------------------------------------
    Column("outcome", "success (force held in the band for the hold time) or timeout (trial cap reached)",
           type="text"),
    Column("cue_at_s", "time of the trial's cue, seconds since the session started (session clock)", "s",
           label="cue at (s)", source="started_at_s", decimals=_T),
    *_trial_metric_columns(),
    Column("first_contact_s", "time from the cue to the first sample with task force above the contact "
           "threshold; empty without contact", "s", label="first contact (s)", decimals=_T),
    *_censored_columns(),
    # -- per participant × mode (× target) ----------------------------------------------------------
    Column("n_trials", "analysed trials", "count", "integer", label="trials", files=_PER),
    *_participant_metric_columns(),
    # -- paired Wilcoxon tests, ON vs OFF -------------------------------------------------------------
    Column("metric", f"the measure tested: {_TESTED} (participants.csv columns)", type="text",
           label="measure"),
    Column("n", "pairs that entered the ranking (n_used)", "count", "integer", label="n", files=_STATS),
    Column("median_off", "median over participants of the OFF values (complete pairs)", _MU,
           label="median OFF", decimals=4),
    Column("median_on", "median over participants of the ON values (complete pairs)", _MU, label="median ON",
           decimals=4),
    Column("statistic", "Wilcoxon signed-rank statistic: the smaller rank sum, min(W+, W−), for a two-sided "
           "test", "rank sum", label="W", decimals=4),
    Column("p_value", "p-value of the Wilcoxon signed-rank test (method: see method)", "probability",
           label="p", files=_STATS, significant=4),
    Column("method", "how the p-value was computed: exact, permutation or approx (normal approximation); "
           "empty when not computable", type="text", label="p method", files=_STATS),
    Column("zero_method", "handling of zero differences: wilcox (dropped), pratt or zsplit", type="text",
           label="zeros"),
    Column("rank_biserial", "matched-pairs rank-biserial correlation (W+ − W−)/(W+ + W−); positive: ON > OFF",
           "−1 to 1", label="rank-biserial", decimals=4),
    Column("p_holm", f"p-value after Holm's step-down correction across the {_FAMILY} measures (within the "
           f"target in stats_by_target.csv){_SECONDARY}", "probability", label="p (Holm)", significant=4),
    Column("n_pairs", "participants with a value in both modes", "count", "integer", label="pairs"),
    Column("n_dropped_nan", "participants left out for lacking a value in a mode (e.g. no successful trial for "
           "TCT)", "count", "integer", label="pairs dropped"),
    Column("n_used", "pairs that entered the ranking", "count", "integer", label="pairs ranked"),
    Column("n_zero", "pairs with a zero difference ON − OFF", "count", "integer", label="zero differences"),
    Column("n_ties", "groups of equal non-zero |ON − OFF| of size > 1", "count", "integer", label="tie groups"),
    Column("z", "tie-corrected normal statistic of W+ (no continuity correction); positive: ON > OFF",
           "standard normal", decimals=4),
    Column("r", "effect size r = z/√n", "−1 to 1", label="r = z/√n", decimals=4),
    Column("hl_estimate", "Hodges–Lehmann estimate of the shift ON − OFF", _MU, label="HL shift", decimals=4),
    Column("hl_ci_low", "lower end of the Hodges–Lehmann confidence interval", _MU, label="HL CI low",
           decimals=4),
    Column("hl_ci_high", "upper end of the Hodges–Lehmann confidence interval", _MU, label="HL CI high",
           decimals=4),
    Column("ci_level", "confidence the Hodges–Lehmann interval achieves", "fraction (0–1)", label="CI level",
           decimals=4),
    Column("computable", "false when no test was possible (see note)", type="boolean", files=_STATS),
    Column("note", "why a test was not computable, or which degenerate case occurred; empty otherwise",
           type="text", files=_STATS),
    Column("alternative", "alternative hypothesis: two-sided, greater (ON > OFF) or less", type="text"),
    Column("w_plus", "rank sum of the pairs with ON > OFF", "rank sum", label="W+", decimals=4),
    Column("w_minus", "rank sum of the pairs with ON < OFF", "rank sum", label="W−", decimals=4),
    Column("n_positive", "pairs with ON > OFF", "count", "integer", label="ON > OFF"),
    Column("n_negative", "pairs with ON < OFF", "count", "integer", label="ON < OFF"),
    # -- speed against accuracy, within participants --------------------------------------------------
    Column("n_trials", "trials with both a TCT and an RMSE (participants' only such trial left out: it has no "
           "within-participant information)", "count", "integer", label="trials", files=_SA),
    Column("n_participants", "participants contributing (at least two such trials in a mode)", "count", "integer",
           label="participants", files=_SA),
    Column("r_rm", "repeated-measures correlation of TCT with RMSE (Bakdash & Marusich 2017): the common "
           "within-participant association; negative: a participant's faster trials were the less accurate ones "
           "(a trade)", "−1 to 1", label="r_rm", decimals=4),
    Column("df", "degrees of freedom of r_rm: trials − participants (− mode cells for 'all') − 1", "count",
           "integer", files=_SA),
    Column("p_value", "p-value of r_rm (t test of the common within-participant slope, df as given)",
           "probability", label="p", files=_SA, significant=4),
    Column("ci_low", "lower end of the confidence interval of r_rm (Fisher z, SE = 1/√(df − 3), as the rmcorr R "
           "package)", "−1 to 1", label="CI low", files=_SA, decimals=4),
    Column("ci_high", "upper end of the confidence interval of r_rm", "−1 to 1", label="CI high", files=_SA,
           decimals=4),
    Column("slope_s_per_N", "common within-participant slope of TCT on RMSE", "s per N", label="slope (s/N)",
           source="slope_s_per_n", decimals=4),
    Column("computable", "false when r_rm could not be computed (see note)", type="boolean", files=_SA),
    Column("note", "why r_rm was not computable, or what was left out; empty otherwise", type="text", files=_SA),
    Column("median_tct_s", "median TCT of the correlated trials", "s", label="median TCT (s)", decimals=_T),
    Column("median_rmse_N", "median RMSE of the correlated trials", "N", label="median RMSE (N)",
           source="median_rmse_n", decimals=_F),
    Column("participant_code", "pseudonymous participant code", type="text", label="participant", files=_SLOPES),
    Column("n_trials", "the participant's trials in this mode with both a TCT and an RMSE", "count", "integer",
           label="trials", files=_SLOPES),
    Column("intercept_s", "TCT at RMSE = 0 of the participant's own least-squares line", "s", label="intercept (s)",
           decimals=_T),
    Column("rmse_min_N", "the participant's smallest RMSE in this mode", "N", source="rmse_min_n", decimals=_F),
    Column("rmse_max_N", "the participant's largest RMSE in this mode", "N", source="rmse_max_n", decimals=_F),
    # -- a moving target: tracking error against the target's speed (analysis.stats.target_speed) --------
    Column("target_speed_N_per_s", "speed of the target: mean |dF*/dt| over the part of the trial where it moves",
           "N/s", label="target speed (N/s)", source="target_speed_n_per_s", decimals=_F),
    Column("rmse_N", "mean RMSE of the participant's trials of this target in this mode", "N", label="RMSE (N)",
           files=_SPEED, decimals=_F),
    Column("n_trials", "the participant's trials of this target in this mode", "count", "integer", label="trials",
           files=_SPEED),
    Column("n_targets", "targets with a mean RMSE in this mode (the points of the line)", "count", "integer",
           label="targets", files=_SPEED_SLOPES),
    Column("rmse_per_speed_s", "least-squares slope of the participant's mean RMSE per target on the targets' "
           "speeds in this mode: N of error per N/s of speed; empty with fewer than two speeds", "s",
           label="RMSE per speed (s)", decimals=4),
    Column("intercept_N", "RMSE at speed 0 of that line", "N", label="intercept (N)", source="intercept_n",
           decimals=_F),
    Column("metric", "the measure tested: rmse_per_speed_s (target_speed_slopes.csv), one value per participant "
           "per mode", type="text", label="measure", files=("target_speed_test.csv",)),
    Column("p_holm", "empty: the slope is tested on its own, outside Holm's family", "probability",
           label="p (Holm)", files=("target_speed_test.csv",), significant=4),
    # -- trial-level models (speed_accuracy_model.csv, learning_models.csv) ------------------------------
    Column("model", "speed-accuracy (TCT ~ RMSE × mode + (1 | participant)) or learning (outcome ~ mode × "
           "target + trial number, participant as the unit)", type="text", files=_MODELS),
    Column("outcome", "the modelled outcome and its unit", type="text", files=_MODELS),
    Column("term", "fixed effect: intercept, haptics_on (ON − OFF), target_<label> (that target − the lowest), "
           "haptics_on_x_target_<label> (interaction), trial_number (per trial), rmse (slope of TCT on RMSE, "
           "OFF), rmse_x_on (ON − OFF difference of that slope); empty when the model was not fitted",
           type="text", files=_MODELS),
    Column("estimate", "the fixed effect's estimate, in the unit given by scale", "see scale", files=_MODELS,
           decimals=6),
    Column("std_error", "its standard error (GEE: robust)", "see scale", files=_MODELS, decimals=6),
    Column("ci_low", "lower end of its Wald confidence interval", "see scale", files=_MODELS, decimals=6),
    Column("ci_high", "upper end of its Wald confidence interval", "see scale", files=_MODELS, decimals=6),
    Column("z", "estimate / standard error", "standard normal", files=_MODELS, decimals=4),
    Column("p_value", "two-sided Wald p-value of the fixed effect", "probability", files=_MODELS, significant=4),
    Column("scale", "unit of the estimates: s, N, log-odds (success; exp(estimate) is an odds ratio)",
           type="text", files=_MODELS),
    Column("n_obs", "trials in the model", "count", "integer", files=_MODELS),
    Column("n_participants", "participants in the model", "count", "integer", files=_MODELS),
    Column("method", "how the model was fitted", type="text", files=_MODELS),
    Column("converged", "false when the fit did not converge or statsmodels warned (see note)", type="boolean",
           files=_MODELS),
    Column("note", "why the model was not fitted, or statsmodels' warnings; empty otherwise", type="text",
           files=_MODELS),
    # -- order check ---------------------------------------------------------------------------------
    Column("n_on_first", "participants whose stored schedule begins with a haptics-ON trial", "count", "integer",
           files=_ORDER),
    Column("n_off_first", "participants whose stored schedule begins with a haptics-OFF trial", "count",
           "integer", files=_ORDER),
    Column("median_diff_on_first", "median ON − OFF difference of the ON-first participants", _MU, decimals=4),
    Column("median_diff_off_first", "median ON − OFF difference of the OFF-first participants", _MU, decimals=4),
    Column("u_statistic", "Mann–Whitney U of the ON-first against the OFF-first differences", "rank count",
           decimals=1),
    Column("p_value", "two-sided p-value of the Mann–Whitney U test (scipy.stats.mannwhitneyu)", "probability",
           files=_ORDER, significant=4),
    Column("computable", "false when the groups are too small to test (see note)", type="boolean", files=_ORDER),
    Column("note", "why not tested; empty otherwise", type="text", files=_ORDER),
    # -- error-window sensitivity --------------------------------------------------------------------
    Column("analysis", f"ON vs OFF (the Wilcoxon tests, Holm across the {_FAMILY} measures) or speed-accuracy "
           "(r_rm)",
           type="text", files=_SENS),
    Column("measure", "the measure tested, or r_rm off / on / all", type="text", files=_SENS),
    Column("error_window", "the error window of this row: cue (from the cue, the approach included) or "
           "first_contact", type="text", files=_SENS),
    Column("n", "pairs ranked (ON vs OFF) or trials correlated (r_rm)", "count", "integer", files=_SENS),
    Column("estimate", "Hodges–Lehmann shift ON − OFF (unit of the measure), or r_rm", "see analysis",
           files=_SENS, decimals=4),
    Column("ci_low", "lower end of its confidence interval", "see analysis", files=_SENS, decimals=4),
    Column("ci_high", "upper end of its confidence interval", "see analysis", files=_SENS, decimals=4),
    Column("p_value", "p-value (Wilcoxon signed-rank test, or the t test of r_rm)", "probability", files=_SENS,
           significant=4),
    Column("p_holm", f"Holm-adjusted p across the {_FAMILY} measures in this window (ON vs OFF only)",
           "probability",
           files=_SENS, significant=4),
    Column("conclusion", "what the row concludes at p < 0.05 (Holm's p for the tests)", type="text", files=_SENS),
    Column("differs", "true when this measure's conclusion is not the same in every error window", type="boolean",
           files=_SENS),
    Column("error_window", "the error window of RMSE, Max AE and peak force in this file: cue (from the cue, the "
           "approach from 0 N included: the paper's 'during the trial') or first_contact", type="text"),
    # -- incomplete sessions, deviations, provenance --------------------------------------------------
    Column("n_finished", "trials that ended as designed (success or timeout)", "count", "integer",
           files=("incomplete_sessions.csv",)),
    Column("n_designed", "trials of the session's design (its schedule less the re-runs of aborted trials)",
           "count", "integer"),
    Column("n_aborted", "aborted trials (not counted)", "count", "integer", files=("incomplete_sessions.csv",)),
    Column("analysed", "true when the session's finished trials are analysed (experiment sessions that "
           "completed, and with --include-incomplete the others)", type="boolean"),
    Column("reason", "why the session is incomplete, in words", type="text", files=("incomplete_sessions.csv",)),
    Column("n_runs", "the runs the session took: 1 when it ran in one go, one more per resume after an "
           "interruption (report.html lists each resume under What was delivered)", "count", "integer",
           files=("sessions.csv",)),
    Column("writer", "the live process running the session while the report was made (\"process N (command)\"); "
           "empty when none: a running session without one was interrupted", type="text", files=("sessions.csv",)),
    Column("kind", "the kind of deviation event (deviation, calibration_override, fault_rehearsal)", type="text",
           files=("deviations.csv",)),
    Column("t_s", "session clock of the event", "s", files=("deviations.csv",), decimals=_T),
    Column("detail", "what the event records, as stored", type="text", files=("deviations.csv",)),
    Column("software_commit", "git commit of the checkout that ran the session; empty when not known (installed "
           "from a wheel, or recorded before schema version 4)", type="text", label="commit"),
    Column("software_dirty", "true when that checkout had uncommitted changes to tracked files; empty when not "
           "known", type="boolean", label="uncommitted changes"),
    Column("first_mode", "haptic mode of the first trial of the session's stored schedule (the order check's "
           "grouping)", type="text", label="first mode"),
    # -- sessions -----------------------------------------------------------------------------------
    Column("kind", "training or experiment (training sessions are not analysed)", type="text"),
    Column("status", "running (interrupted, resumable), completed or aborted", type="text"),
    Column("seed", "study seed the session's schedule was drawn with", type="integer"),
    Column("started_at", "when the session started, ISO 8601 UTC", type="text", label="started"),
    Column("ended_at", "when the session ended, ISO 8601 UTC; empty if interrupted", type="text", label="ended"),
    Column("end_reason", "why the session ended early; empty otherwise", type="text", label="end reason"),
    Column("software_version", "haptic-study version that recorded the session", type="text", label="software"),
    Column("rig", "sim (simulated rig: simulated data) or real (the hardware)", type="text"),
    Column("protocol_name", "name of the protocol the session ran", type="text", label="protocol"),
    *(task_column(p) for cls in TASKS.values() for p in cls.described),  # each task's parameters: the task's words
    Column("max_trial_s", "trial cap: a trial not completed by then is a timeout", "s", label="trial cap (s)",
           decimals=_T),
    # -- what was delivered: aborted trials and the loop's health per trial ----------------------------
    Column("outcome", "success, timeout, or aborted (not counted; see abort_cause)", type="text",
           files=("loop_health.csv",)),
    Column("abort_cause", "why an aborted trial did not count: experimenter, fault (a watchdog fault latched, "
           "LOOP_STALLED included), feedback (haptics not as designed, thermal derating included), gap (loop "
           "records missing), interrupted (the program ended) or participant_screen (the participant screen "
           "closed, so the cue was not seen); empty for a counted trial or when not recorded "
           "(schema version 1)", type="text", label="abort cause"),
    Column("period_p50_ms", "median haptic-loop tick period over the trial's samples", "ms",
           label="period p50 (ms)", decimals=3),
    Column("period_p99_ms", "99th percentile of the tick period (per participant: the largest over the trials)",
           "ms", label="period p99 (ms)", decimals=3),
    Column("period_max_ms", "longest tick period", "ms", label="period max (ms)", decimals=3),
    Column("periods_over_2ms", "ticks whose period exceeded 2 ms", "count", "integer", label="ticks > 2 ms"),
    Column("sensor_age_max_ms", "age of the oldest F/T sample the loop used (watchdog limit 5 ms)", "ms",
           label="sensor age max (ms)", decimals=3),
    Column("pose_age_max_ms", "age of the oldest robot pose the loop used (watchdog limit 50 ms)", "ms",
           label="pose age max (ms)", decimals=3),
    Column("latency_p50_ms", "median time from an F/T sample's arrival to the force command it produced "
           "(per participant: the median over the trials)", "ms", label="latency p50 (ms)", decimals=3),
    Column("latency_max_ms", "longest time from an F/T sample's arrival to its force command", "ms",
           label="latency max (ms)", decimals=3),
    Column("within_bounds", "true when every loop-health value is within the report's bounds; empty when the "
           "trial has no loop record", type="boolean", label="within bounds"),
    Column("outside_bounds", "which bounds the trial's loop exceeded, in words; empty when within", type="text",
           label="outside bounds"),
    Column("watchdog_sensor_max_age_ms", "the watchdog's F/T sample age limit the session ran with", "ms",
           label="sensor age limit (ms)", decimals=3),
    Column("watchdog_pose_max_age_ms", "the watchdog's robot pose age limit the session ran with", "ms",
           label="pose age limit (ms)", decimals=3),
    Column("pipeline_settings", "the pipeline settings the session ran with that are not the paper's "
           "(haptic-study run --set), as NAME=VALUE, comma-separated; empty: the paper's", type="text",
           label="pipeline settings"),
    Column("n_trials", "experiment trials with a loop record", "count", "integer", label="trials",
           files=("loop_health_by_participant.csv",)),
    Column("n_outside_bounds", "of those, trials outside the bounds", "count", "integer", label="outside bounds"),
    # -- power.csv (report --power): the power of each test against the number of participants ----------
    Column("scope", "overall, or the target level the tests were restricted to", type="text", files=("power.csv",)),
    Column("metric", f"the measure tested (participants.csv column), or all_{_FAMILY}_holm / any_holm: Holm across the "
           f"{_FAMILY} measures rejects all of them / at least one", type="text", files=("power.csv",)),
    Column("direction", "the direction of effect the resampled pool shows (its signed-rank statistic W+ above or "
           "below its null mean): on_higher (ON > OFF), on_lower (ON < OFF) or none; a rejection counts towards "
           "power only in this direction (empty on the family rows)", type="text", files=("power.csv",)),
    Column("n", "participants in each resampled study", "count", "integer", files=("power.csv",)),
    Column("resamples", "resampled studies of n participants", "count", "integer", files=("power.csv",)),
    Column("alpha", "significance level of each test", "probability", files=("power.csv",), decimals=4),
    Column("rejections", "resampled studies whose two-sided test rejected (p < alpha) with the effect in the "
           "pool's direction", "count", "integer", files=("power.csv",)),
    Column("power", "rejections / resamples: the estimated power to detect the effect in the pool's direction",
           "fraction (0–1)", files=("power.csv",), decimals=4),
    Column("ci_low", "lower end of the Clopper–Pearson interval of the power (Monte Carlo error only)",
           "fraction (0–1)", files=("power.csv",), decimals=4),
    Column("ci_high", "upper end of that interval", "fraction (0–1)", files=("power.csv",), decimals=4),
    Column("rejections_two_sided", "resampled studies whose two-sided test rejected, in either direction (empty on "
           "the family rows)", "count", "integer", files=("power.csv",)),
    Column("power_two_sided", "rejections_two_sided / resamples: the two-sided rejection rate", "fraction (0–1)",
           files=("power.csv",), decimals=4),
    Column("two_sided_ci_low", "lower end of the interval of power_two_sided", "fraction (0–1)",
           files=("power.csv",), decimals=4),
    Column("two_sided_ci_high", "upper end of the interval of power_two_sided", "fraction (0–1)",
           files=("power.csv",), decimals=4),
    Column("rejections_holm", "directional rejections that survive Holm's correction across the "
           f"{_FAMILY} measures{_SECONDARY}",
           "count", "integer", files=("power.csv",)),
    Column("power_holm", "power after Holm's correction", "fraction (0–1)", files=("power.csv",), decimals=4),
    Column("holm_ci_low", "lower end of the interval of power_holm", "fraction (0–1)", files=("power.csv",),
           decimals=4),
    Column("holm_ci_high", "upper end of the interval of power_holm", "fraction (0–1)", files=("power.csv",),
           decimals=4),
    Column("mean_pairs", "mean number of pairs that entered the test (a participant without a value in a mode "
           "is left out)", "count", files=("power.csv",), decimals=4),
    Column("not_computable", "resampled studies where no test was possible", "count", "integer", files=("power.csv",)),
    Column("exact", "resampled studies tested with the exact null distribution", "count", "integer",
           files=("power.csv",)),
    Column("permutation", "resampled studies tested by permutation (ties or zeros)", "count", "integer",
           files=("power.csv",)),
    Column("approx", "resampled studies tested with the normal approximation", "count", "integer",
           files=("power.csv",)),
    Column("source", "whose participants were resampled: this study, a pilot database, or the simulated pool",
           type="text", files=("power.csv",)),
    # -- the codebook itself --------------------------------------------------------------------------
    Column("file", "CSV file of the report folder", type="text", files=("codebook.csv",)),
    Column("column", "column of that file", type="text", files=("codebook.csv",)),
    Column("type", "text, integer, number or boolean (true/false)", type="text", files=("codebook.csv",)),
    Column("unit", "unit of the column's values; empty for text and codes", type="text", files=("codebook.csv",)),
    Column("description", "what the column holds", type="text", files=("codebook.csv",)),
)
