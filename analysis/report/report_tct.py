"""report.html's section on task completion time as a time to event, and its sentences in the methods.

Both readings of TCT are on the page with their n -- the figure's (every trial, a failure at the cap: the report's
default and the one tested in Holm's family) and the text's (successful trials only) -- beside the Kaplan–Meier
curves of the time to success and the Cox model's hazard ratio (:mod:`analysis.stats.survival`).  Nothing here
computes a statistic.
"""

from __future__ import annotations

import html
import math
from typing import Any

from analysis.reading.metrics import MetricOptions
from analysis.report.html_parts import fmt, fmt_p, img, plural

__all__ = ["tct_html", "tct_methods"]


def _p(p: float) -> str:
    """``= 0.0123`` or ``< 0.0001``: a p-value after its symbol."""
    text = fmt_p(p)
    return text if text.startswith("&lt;") else f"= {text}"


def _reading_rows(within: Any, options: MetricOptions) -> str:
    """One row per mode: trials, successes, the restricted mean (every trial) and the successful-trials mean, each
    with its n, and the Kaplan–Meier median."""
    rows = []
    for r in within.tte.itertuples():
        med = fmt(r.km_median_s) if math.isfinite(r.km_median_s) else "not reached (fewer than half succeeded)"
        ok = int(r.n_successes)
        rows.append(f"<tr><td class=\"m\">haptics {html.escape(str(r.haptic_mode).upper())}</td><td>{r.n_trials}</td>"
                    f"<td>{ok} ({ok / r.n_trials:.0%})</td><td>{fmt(r.restricted_mean_s)} (n = {r.n_trials})</td>"
                    f"<td>{fmt(r.successful_mean_s)} (n = {ok})</td><td>{med}</td></tr>")
    return "".join(rows)


def _participants_line(within: Any, tables: dict[str, Any]) -> str:
    """How many participants have a TCT in each mode under the successful-trials reading, and how many pairs."""
    per = tables["participants.csv"]
    sens = within.sensitivity
    succ = sens[(sens["analysis"] == "TCT reading") & (sens["reading"] == "successful")]
    n_pairs = int(succ["n"].iloc[0]) if len(succ) else 0
    n_all = int(per["participant_code"].nunique())
    counts = {m: int((per.loc[per["haptic_mode"] == m, "n_success"] > 0).sum()) for m in ("off", "on")}
    return (f"Over successful trials only, {counts['off']} of {plural(n_all, 'participant')} have a TCT with "
            f"haptics OFF and {counts['on']} with haptics ON, so its test has {plural(n_pairs, 'ranked pair')}; "
            "a participant with one success in a mode has a TCT of that one trial. Every trial counts in the "
            "figure's reading and in the time to event.")


def tct_html(within: Any, tables: dict[str, Any], options: MetricOptions, png: bytes, confidence: float) -> str:
    """The section: both readings with their n, the Kaplan–Meier figure, the Cox model's hazard ratio."""
    cox = within.cox
    on = cox.term("haptics_on") if cox.fitted else None
    if on is not None:
        hr = float(on["hazard_ratio"])
        how = "sooner" if hr > 1 else "later"
        model = (f"<p><b>Hazard ratio, haptics ON : OFF = {fmt(hr, 2)} [{fmt(float(on['ci_low']), 2)}, "
                 f"{fmt(float(on['ci_high']), 2)}]</b> ({confidence:.0%} interval), p {_p(float(on['p_value']))}: "
                 f"at any moment, a trial not yet successful reached success {fmt(hr, 2)} times as often with "
                 f"feedback ({how}), at a fixed target, within participants. Cox model stratified by participant "
                 f"(each their own baseline), standard errors clustered on the participant; "
                 f"{plural(cox.n_trials, 'trial')} ({cox.n_events} successful), "
                 f"{plural(cox.n_participants, 'participant')} (survival_model.csv).</p>")
    else:
        model = f'<p class="warn">Cox model {html.escape(cox.note)}.</p>'
    default = "every trial, a failure at the cap" if options.tct_policy == "censored" else "successful trials only"
    table = (f'<div class="scroll"><table class="within"><caption>TCT in both readings (time_to_event.csv); the '
             f"tests use: {default}</caption><thead><tr><th>trials of</th><th>trials</th><th>successes</th>"
             "<th>mean TCT, every trial, failure at the cap (s)</th><th>mean TCT, successful trials (s)</th>"
             "<th>Kaplan–Meier median (s)</th></tr></thead>"
             f"<tbody>{_reading_rows(within, options)}</tbody></table></div>")
    return ("<h2>Task completion time as a time to event</h2><p>The paper's text defines TCT over successful trials; "
            "its figure averages it over every trial with a failure at the 12 s cap. A trial that did not succeed "
            "by the cap has a time to success that is <i>censored</i> there: it is known only to exceed the cap. "
            f"Both readings are given with their n, and the time to success is analysed as censored. "
            f"{_participants_line(within, tables)}</p>{table}{model}"
            f"<figure>{img(png, 'Kaplan–Meier curves of the time to success per haptic mode')}</figure>"
            '<p class="caption">Kaplan–Meier estimate of P(no success yet) per mode, every trial of every '
            "participant, a failure censored at the cap; bands: pointwise log-log intervals, descriptive (trials of "
            "one participant are not independent: the inference is the Cox model's). kaplan_meier.csv has every "
            "step.</p>")


def tct_methods(within: Any, options: MetricOptions, confidence: float) -> str:
    """The methods' paragraph on TCT: the two readings, which one is tested, and the time-to-event analysis."""
    tested = ("every trial, a failed trial counted at the trial cap (the paper's figure: the restricted mean time "
              "to success)" if options.tct_policy == "censored" else
              "successful trials only (the paper's text; a participant with no success in a mode has no TCT there "
              "and that pair is left out)")
    return (f"<p><b>Task completion time.</b> The per-participant TCT that enters the tests is the mean over "
            f"{tested}; the other reading is given beside it with its n, and in the sensitivity table. As a time "
            "to event, each trial's time to success is censored at the cap when it failed: Kaplan–Meier curves per "
            "mode (scipy.stats.ecdf on censored data, pointwise log-log intervals) and a Cox proportional-hazards "
            "model of the time to success with haptics ON and the target as covariates, stratified by participant, "
            "with sandwich standard errors clustered on the participant (statsmodels PHReg, Efron's ties), give the "
            f"hazard ratio ON : OFF with its {confidence:.0%} Wald interval. No parameter is chosen by its "
            "p-value.</p>")
