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

__all__ = ["COLUMNS", "DIFFERENCE_DECIMALS", "STATS_CSV_COLUMNS", "Column", "metric_words", "participant_measures",
           "task_column"]


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


#: The decimals a paired test rounds its differences ON − OFF to before ranking, so that differences equal in exact
#: arithmetic tie in floating point (:func:`analysis.stats.wilcoxon.paired_wilcoxon`); participants_wide.csv's
#: differences are written so, for a test of them elsewhere to rank as the report's does.
DIFFERENCE_DECIMALS = 10

_STATS = ("stats.csv", "stats_by_target.csv", "stats_by_site.csv", "target_speed_test.csv")
#: The tests' files (:data:`_STATS`): the columns every consumer may rely on, first and in this order (more follow).
STATS_CSV_COLUMNS = ("metric", "n", "median_off", "median_on", "statistic", "p_value", "method",
                     "zero_method", "rank_biserial", "p_holm")
_SA = ("speed_accuracy.csv",)
_SLOPES = ("speed_accuracy_slopes.csv",)
_MODELS = ("speed_accuracy_model.csv", "learning_models.csv")
_ORDER = ("order_check.csv",)
_SENS = ("sensitivity.csv",)
_PER = ("participants.csv", "participants_by_target.csv")
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
    Column("targets_balanced", "false where the participant's trials in this mode are not spread equally over the "
           "targets (an incomplete session analysed, --include-incomplete): the mode's values are then the mean of "
           "the per-target values, each target weighing the same as in the design", type="boolean",
           files=("participants.csv",)),
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
    Column("rank_biserial_ci_low", "lower end of the bootstrap interval of the rank-biserial correlation "
           "(participants resampled, 9999 times, fixed seed; see rank_biserial_ci_method)", "−1 to 1", decimals=4),
    Column("rank_biserial_ci_high", "upper end of that interval", "−1 to 1", decimals=4),
    Column("rank_biserial_ci_method", "BCa (bias-corrected and accelerated), or percentile where every resample "
           "gives the same value (BCa undefined); empty when not computable", type="text"),
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
    Column("status", "completed, aborted (by the experimenter), interrupted (the program ended during it: stored as "
           "running, resumable, as haptic-study sessions says) or in progress (a live process runs it)",
           type="text"),
    Column("site", "the site of the session's database (report --site); empty when none was named; its participant "
           "codes are then SITE:CODE", type="text", files=("sessions.csv",)),
    Column("protocol_version", "version of the protocol the session ran", type="integer", files=("sessions.csv",)),
    Column("training_enabled", "the protocol has a training session before the experiment", type="boolean"),
    Column("training_cap_s", "the protocol's training trial cap (training.seconds_per_target_per_mode): each "
           "training trial ends at a completed hold or after this long", "s", decimals=_T),
    Column("training_live_aid", "the protocol shows a live force gauge and the target band in training "
           "(training.live_force_aid)", type="boolean"),
    Column("training_required", "an experiment session needed a completed training session "
           "(training.required)", type="boolean"),
    Column("n_trials", "trials the session stored (aborted ones included)", "count", "integer",
           files=("sessions.csv",)),
    Column("n_success", "of them, successful", "count", "integer", files=("sessions.csv",)),
    Column("trial_time_s", "the session's trials' summed length, cue to end (a training session: the time "
           "trained)", "s", files=("sessions.csv",), decimals=_T),
    Column("live_force_aid", "the session showed the live force gauge and band (a training session whose protocol "
           "asks for it; never an experiment session)", type="boolean", files=("sessions.csv",)),
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
