"""The codebook's entries of the analyses beyond the ON-vs-OFF tests: the speed–accuracy trade, the models, the order
check, the sensitivity table, TCT as a time to event, a moving target's speed and the sites
(:mod:`analysis.reading.codebook_columns` has the trials, the participants, the tests and the record;
:mod:`analysis.reading.codebook` reads both).
"""

from __future__ import annotations

from analysis.reading.codebook_columns import _F, _FAMILY, _MU, _T, Column

__all__ = ["WITHIN_COLUMNS"]

_SA = ("speed_accuracy.csv",)
_SLOPES = ("speed_accuracy_slopes.csv",)
_MODELS = ("speed_accuracy_model.csv", "learning_models.csv")
_ORDER = ("order_check.csv",)
_SENS = ("sensitivity.csv",)
_TTE = ("time_to_event.csv",)
_KM = ("kaplan_meier.csv",)
_COX = ("survival_model.csv",)
_SITE = ("site_differences.csv",)
_SPEED, _SPEED_SLOPES = ("target_speed.csv",), ("target_speed_slopes.csv",)

WITHIN_COLUMNS: tuple[Column, ...] = (
    # -- speed against accuracy, within participants --------------------------------------------------
    Column("reading", "how speed and accuracy were measured: phases (rise time against RMSE after reaching the "
           "band, the default: parts of the trial that do not overlap), cue (TCT of the successful trials against "
           "RMSE from the cue, the approach included) or first_contact (the same, RMSE from first contact)",
           type="text", files=_SA),
    Column("speed", "the speed measure (trials.csv column): rise_time_s or tct_s", type="text", files=_SA),
    Column("accuracy", "the accuracy measure (trials.csv column): reach_rmse_N or rmse_N (in the reading's window)",
           type="text", files=_SA),
    Column("n_trials", "trials with both measures (a participant's only such trial in a mode left out: it has no "
           "within-participant information)", "count", "integer", label="trials", files=_SA),
    Column("n_participants", "participants contributing (at least two such trials in a mode)", "count", "integer",
           label="participants", files=_SA),
    Column("r_rm", "repeated-measures correlation of speed with accuracy (Bakdash & Marusich 2017): the common "
           "within-participant association; negative: a participant's faster trials were the less accurate ones",
           "−1 to 1", label="r_rm", decimals=4),
    Column("df", "degrees of freedom of r_rm: trials − participants (− mode cells for 'all') − 1", "count",
           "integer", files=_SA),
    Column("p_value", "p-value of r_rm (t test of the common within-participant slope, df as given)",
           "probability", label="p", files=_SA, significant=4),
    Column("ci_low", "lower end of the confidence interval of r_rm (Fisher z of a partial correlation, "
           "SE = 1/√(df − 1), as pingouin's rm_corr; empty for df < 2)", "−1 to 1", label="CI low", files=_SA,
           decimals=4),
    Column("ci_high", "upper end of the confidence interval of r_rm", "−1 to 1", label="CI high", files=_SA,
           decimals=4),
    Column("slope_s_per_N", "common within-participant slope of speed on accuracy", "s per N", label="slope (s/N)",
           source="slope_s_per_n", decimals=4),
    Column("computable", "false when r_rm could not be computed (see note)", type="boolean", files=_SA),
    Column("note", "why r_rm was not computable, or what was left out; empty otherwise", type="text", files=_SA),
    Column("conclusion", "what the row concludes from the interval of r_rm: only the phases reading names a trade, "
           "and only where its interval lies below 0 and the cue reading's does too", type="text", files=_SA),
    Column("median_speed_s", "median speed measure of the correlated trials", "s", label="median speed (s)",
           decimals=_T),
    Column("median_accuracy_N", "median accuracy measure of the correlated trials", "N", label="median accuracy (N)",
           source="median_accuracy_n", decimals=_F),
    Column("participant_code", "pseudonymous participant code", type="text", label="participant", files=_SLOPES),
    Column("n_trials", "the participant's trials in this mode with a rise time and an RMSE after reach", "count",
           "integer", label="trials", files=_SLOPES),
    Column("intercept_s", "rise time at RMSE after reach = 0 of the participant's own least-squares line", "s",
           label="intercept (s)", decimals=_T),
    Column("accuracy_min_N", "the participant's smallest RMSE after reach in this mode", "N",
           source="accuracy_min_n", decimals=_F),
    Column("accuracy_max_N", "the participant's largest RMSE after reach in this mode", "N",
           source="accuracy_max_n", decimals=_F),
    # -- trial-level models (speed_accuracy_model.csv, learning_models.csv) ------------------------------
    Column("model", "speed-accuracy (rise time ~ RMSE after reach × mode (+ site) + (1 + mode | participant)) or "
           "learning (outcome ~ mode × target + trial number (+ site), participant as the unit)", type="text",
           files=_MODELS),
    Column("outcome", "the modelled outcome and its unit", type="text", files=_MODELS),
    Column("term", "fixed effect: intercept, haptics_on (ON − OFF), target_<label> (that target − the lowest), "
           "haptics_on_x_target_<label> (interaction), trial_number (per trial), site_<name> (that site − the "
           "first), accuracy (slope of rise time on RMSE after reach, OFF), accuracy_x_on (ON − OFF difference of "
           "that slope); empty when the model was not fitted", type="text", files=_MODELS),
    Column("estimate", "the fixed effect's estimate, in the unit given by scale", "see scale", files=_MODELS,
           decimals=6),
    Column("std_error", "its standard error (GEE: Mancl–DeRouen bias-reduced sandwich)", "see scale", files=_MODELS,
           decimals=6),
    Column("ci_low", "lower end of its Wald confidence interval", "see scale", files=_MODELS, decimals=6),
    Column("ci_high", "upper end of its Wald confidence interval", "see scale", files=_MODELS, decimals=6),
    Column("z", "estimate / standard error", "standard normal", files=_MODELS, decimals=4),
    Column("p_value", "two-sided Wald p-value of the fixed effect", "probability", files=_MODELS, significant=4),
    Column("scale", "unit of the estimates: s, N, log-odds (success; exp(estimate) is an odds ratio)",
           type="text", files=_MODELS),
    Column("n_obs", "trials in the model", "count", "integer", files=_MODELS),
    Column("n_participants", "participants in the model", "count", "integer", files=_MODELS),
    Column("method", "how the model was fitted (a mixed model: with a random slope of mode where it could be "
           "fitted)", type="text", files=_MODELS),
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
    # -- sensitivity: the error window, the TCT reading, the speed–accuracy reading -------------------------
    Column("analysis", "error window (the ON-vs-OFF tests of the windowed measures, Holm across the "
           f"{_FAMILY} in each window), TCT reading (TCT's test with failures at the cap or over successful trials "
           "only, and the Cox model's hazard ratio) or speed-accuracy (r_rm)", type="text", files=_SENS),
    Column("measure", "the measure tested, or r_rm off / on / all", type="text", files=_SENS),
    Column("reading", "the row's reading: cue or first_contact (error window); censored, successful or "
           "time_to_event (TCT); phases, cue or first_contact (speed-accuracy)", type="text", files=_SENS),
    Column("default", "true for the reading the report's other tables use", type="boolean", files=_SENS),
    Column("n", "pairs ranked (tests), trials (time to event) or trials correlated (r_rm)", "count", "integer",
           files=_SENS),
    Column("estimate", "Hodges–Lehmann shift ON − OFF (unit of the measure), the hazard ratio of success ON : OFF "
           "(time to event), or r_rm", "see analysis", files=_SENS, decimals=4),
    Column("ci_low", "lower end of its confidence interval", "see analysis", files=_SENS, decimals=4),
    Column("ci_high", "upper end of its confidence interval", "see analysis", files=_SENS, decimals=4),
    Column("p_value", "p-value (Wilcoxon signed-rank test, the Cox model's Wald test, or the t test of r_rm)",
           "probability", files=_SENS, significant=4),
    Column("p_holm", f"Holm-adjusted p across the {_FAMILY} measures under this reading (tests only)",
           "probability", files=_SENS, significant=4),
    Column("conclusion", "what the row concludes at p < 0.05 (Holm's p for the tests; the interval for r_rm)",
           type="text", files=_SENS),
    Column("differs", "true when this measure's conclusion is not the same under every reading", type="boolean",
           files=_SENS),
    # -- TCT as a time to event -----------------------------------------------------------------------
    Column("n_trials", "analysed trials of the mode", "count", "integer", files=_TTE),
    Column("n_successes", "of them, successful (an event); the others are censored at the trial cap", "count",
           "integer", files=_TTE),
    Column("n_participants", "participants with trials in the mode", "count", "integer", files=_TTE),
    Column("km_median_s", "Kaplan–Meier median time to success: the first time the curve is at or below 0.5; "
           "empty when it stays above (fewer than half the trials succeeded)", "s", files=_TTE, decimals=_T),
    Column("restricted_mean_s", "mean of min(TCT, cap) over every trial: the TCT of the paper's figure (a failure "
           "at the cap), the restricted mean time to success", "s", files=_TTE, decimals=_T),
    Column("successful_mean_s", "mean TCT over the successful trials only (the paper's text's reading; n: "
           "n_successes)", "s", files=_TTE, decimals=_T),
    Column("time_s", "time since the cue of the curve's step (0: its start)", "s", files=_KM, decimals=_T),
    Column("n_at_risk", "trials not yet successful nor censored just before this time", "count", "integer",
           files=_KM),
    Column("n_events", "trials that succeeded at this time", "count", "integer", files=_KM),
    Column("survival", "Kaplan–Meier estimate of P(no success yet) after this time", "fraction (0–1)", files=_KM,
           decimals=4),
    Column("ci_low", "lower end of its pointwise log-log (Greenwood) interval; trials are pooled over "
           "participants, so it is descriptive (too narrow for inference: the Cox model is the inference)",
           "fraction (0–1)", files=_KM, decimals=4),
    Column("ci_high", "upper end of that interval", "fraction (0–1)", files=_KM, decimals=4),
    Column("term", "haptics_on (ON against OFF) or target_<label> (that target against the lowest); empty when not "
           "fitted", type="text", files=_COX),
    Column("hazard_ratio", "exp(coef): how many times the hazard of success (success sooner) the term multiplies; "
           "above 1 for haptics_on: ON reaches success sooner", "ratio", files=_COX, decimals=4),
    Column("ci_low", "lower end of the hazard ratio's Wald interval (clustered standard error)", "ratio",
           files=_COX, decimals=4),
    Column("ci_high", "upper end of that interval", "ratio", files=_COX, decimals=4),
    Column("coef", "the Cox model's coefficient, the log hazard ratio", "log ratio", files=_COX, decimals=6),
    Column("std_error", "its sandwich standard error, clustered on the participant", "log ratio", files=_COX,
           decimals=6),
    Column("z", "coef / std_error", "standard normal", files=_COX, decimals=4),
    Column("p_value", "two-sided Wald p-value (clustered standard error)", "probability", files=_COX,
           significant=4),
    Column("model_std_error", "the model-based standard error, for comparison (trials treated as independent "
           "given the participant's stratum)", "log ratio", files=_COX, decimals=6),
    Column("n_trials", "trials in the model", "count", "integer", files=_COX),
    Column("n_events", "successful trials (events)", "count", "integer", files=_COX),
    Column("n_participants", "participants (strata and clusters)", "count", "integer", files=_COX),
    Column("method", "how the model was fitted", type="text", files=_COX),
    Column("note", "why it was not fitted, or statsmodels' warnings; empty otherwise", type="text", files=_COX),
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
    # -- sites ---------------------------------------------------------------------------------------
    Column("site", "the site of the row (report --site); empty when no site was named", type="text"),
    Column("metric", "the measure whose ON − OFF differences are compared between the sites", type="text",
           files=_SITE),
    Column("n_sites", "sites compared", "count", "integer", files=_SITE),
    Column("n_participants", "participants with both modes", "count", "integer", files=_SITE),
    Column("medians_by_site", "each site's median ON − OFF difference and its participants", type="text",
           files=_SITE),
    Column("h_statistic", "Kruskal–Wallis H of the differences between the sites (scipy.stats.kruskal)",
           "chi-square", files=_SITE, decimals=4),
    Column("df", "its degrees of freedom: sites − 1", "count", "integer", files=_SITE),
    Column("p_value", "p-value of H: does the effect of feedback differ between the sites?", "probability",
           files=_SITE, significant=4),
    Column("computable", "false when not tested (see note)", type="boolean", files=_SITE),
    Column("note", "why not tested; empty otherwise", type="text", files=_SITE),
)
