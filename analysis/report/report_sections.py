"""The sections of report.html that look within participants and at the record: written from computed results.

* :func:`trade_html` -- the speed–accuracy trade: repeated-measures correlations, the mixed model, the slopes;
* :func:`sensitivity_html` -- the headline results under every error window, differing conclusions flagged;
* :func:`secondary_html` -- learning and order, labelled as the secondary analysis it is;
* :func:`incomplete_html`, :func:`deviations_html`, :func:`provenance_html`, :func:`top_warnings` -- what
  the record says: incomplete sessions and why, recorded deviations, which code ran which session;
* :func:`methods_within` and :func:`window_fact` -- their sentences for the methods section.

Nothing here computes a statistic; every number comes from :mod:`analysis.stats.trade`,
:mod:`analysis.stats.sensitivity`, :mod:`analysis.stats.learning` or :mod:`analysis.report.study_record`.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from typing import Any

import pandas as pd

from analysis.reading import codebook
from analysis.reading.metrics import MetricOptions
from analysis.report.html_parts import fmt, fmt_p, html_table, img, plural
from analysis.report.measures import listed, windowed_words
from analysis.stats.learning import MIN_ORDER_GROUP
from analysis.stats.models import MIN_PARTICIPANTS
from analysis.stats.sensitivity import ALPHA
from analysis.stats.trade import TRADE_MODEL_TERMS
from protocol.metrics import Metric, tested

__all__ = ["deviations_html", "incomplete_html", "methods_within", "provenance_html", "resumed_html", "secondary_html",
           "sensitivity_html", "short_commit", "top_warnings", "trade_html", "window_fact", "window_words"]

_MODE = {"off": "haptics OFF", "on": "haptics ON", "all": "both modes (within participant × mode)"}
_MODEL_COLS = ["term", "estimate", "ci", "p_value"]


def window_words(window: str) -> str:
    """``from the cue`` or ``from first contact``: how a table caption names the error window."""
    return "from the cue (error window: cue)" if window == "cue" else "from first contact (error window: first_contact)"


def short_commit(v: object) -> str:
    """A commit as a table shows it: its first 12 hex digits, or "not known"."""
    return html.escape(v[:12]) if isinstance(v, str) and v else "not known"


def _ci(lo: object, hi: object, digits: int = 3) -> str:
    lo_f, hi_f = float(lo), float(hi)  # type: ignore[arg-type]  # a number from the model table (NaN when missing)
    return f"[{fmt(lo_f, digits)}, {fmt(hi_f, digits)}]" if math.isfinite(lo_f) else "–"


def _ci_heading(confidence: float) -> str:
    """``95 % CI`` at the level the report was made with (``--confidence``): the intervals' own level."""
    return f"{confidence * 100:g} % CI"


def _model_table(fe: pd.DataFrame, labels: dict[str, str], caption: str, confidence: float = 0.95) -> str:
    """A fixed-effects table (:func:`analysis.stats.models.fixed_effects` rows of one or more fits).

    A fitted model's note (a warning of the fit, the participant variance at its boundary) is a footnote marked
    on each of its rows; an unfitted model is one row with its note.
    """
    notes = list(dict.fromkeys(str(n) for n, t in zip(fe["note"], fe["term"], strict=True)
                               if t and isinstance(n, str) and n))
    marks = {n: "†" * (k + 1) if k < 3 else str(k + 1) for k, n in enumerate(notes)}
    body = []
    for r in fe.itertuples():
        if not r.term:
            body.append(f'<tr class="nc"><td class="m">{html.escape(str(r.outcome))}</td>'
                        f'<td colspan="4" class="wrap">{html.escape(str(r.note))}</td></tr>')
            continue
        warn = f" <sup>{marks[str(r.note)]}</sup>" if str(r.note) in marks else ""
        body.append(f'<tr><td class="m">{html.escape(str(r.outcome))}</td>'
                    f'<td class="m">{html.escape(labels.get(r.term, r.term))}{warn}</td>'
                    f"<td>{fmt(r.estimate, 4)}</td><td>{_ci(r.ci_low, r.ci_high, 4)}</td>"
                    f"<td>{fmt_p(r.p_value)}</td></tr>")
    foot = "".join(f"<li>{k}: {html.escape(n)}</li>" for n, k in marks.items())
    return (f'<div class="scroll"><table class="within"><caption>{caption}</caption><thead><tr><th>outcome</th>'
            f"<th>term</th><th>estimate</th><th>{_ci_heading(confidence)}</th><th>p</th></tr></thead>"
            f'<tbody>{"".join(body)}</tbody></table></div>' + (f'<ul class="notes">{foot}</ul>' if foot else ""))


def trade_html(within: Any, tables: dict[str, pd.DataFrame], options: MetricOptions, png: bytes,
               confidence: float = 0.95) -> str:
    """The speed–accuracy section: r_rm per mode under the default reading with its conclusion, the sensitivity
    readings beside it, the mixed model's fixed effects and the slopes figure."""
    from analysis.stats.models import fixed_effects

    rows = "".join(
        f"<tr><td class=\"m\">{html.escape(_READING[r.reading])}</td><td class=\"m\">{_MODE[r.haptic_mode]}</td>"
        f"<td>{int(r.n_trials)}</td><td>{int(r.n_participants)}</td><td>{fmt(r.r_rm)}</td>"
        f"<td>{_ci(r.ci_low, r.ci_high)}</td><td>{int(r.df)}</td><td>{fmt_p(r.p_value)}</td>"
        f"<td class=\"wrap\"><i>{html.escape(str(r.conclusion))}</i>"
        f"{'<br>' + html.escape(str(r.note)) if str(r.note) else ''}</td></tr>"
        for r in within.trade.itertuples())
    sa = (f'<div class="scroll"><table class="within"><caption>Repeated-measures correlation of speed with accuracy, '
          f"every reading (speed_accuracy.csv); the first is the report's</caption><thead><tr><th>reading</th>"
          f"<th>trials of</th><th>trials</th><th>participants</th><th>r_rm</th><th>{_ci_heading(confidence)}</th>"
          f"<th>df</th><th>p</th><th>conclusion</th></tr></thead><tbody>{rows}</tbody></table></div>")
    labels = {**TRADE_MODEL_TERMS, **{t: f"{t.removeprefix('site_')} − the first site (s)"
                                      for t in fixed_effects([within.trade_fit])["term"] if str(t).startswith("site_")}}
    model = _model_table(fixed_effects([within.trade_fit]), labels,
                         "Linear mixed model rise time ~ RMSE after reach × mode (+ site) + (1 + mode | "
                         "participant), REML", confidence)
    return ("<h2>Speed against accuracy</h2><p>Is a participant's faster trial a less accurate one? Speed and "
            "accuracy are measured on parts of the trial that do not contain each other: the <b>rise time</b>, from "
            "first contact to the force first reaching the band, and the <b>RMSE over the 1 s after</b> it reached "
            "the band, a window of the same length in every trial (docs/science.md §6.1). Every trial that reached "
            "the band counts, failed or not. The repeated-measures correlation r_rm (Bakdash &amp; Marusich 2017) is "
            "the common within-participant association, free of the differences between people. A negative r_rm: a "
            "participant's faster rises were followed by larger errors. It is called a trade only where its interval "
            "lies below zero <i>and</i> the cue reading agrees. The cue and first-contact readings (TCT of the "
            "successful trials against RMSE from the cue or from first contact) are kept as sensitivity readings: "
            "from the cue, the approach at 0 N is in both TCT and RMSE, so a trial whose hold came quickly has a "
            "larger share of approach in its RMSE -- a negative correlation the window builds. No p-value here "
            f"treats trials as independent.</p>{sa}{model}"
            f"<figure>{img(png, 'rise time against RMSE after reach per mode, participant lines, the common slope')}"
            "</figure><p class=\"caption\">Dots: trials; thin lines: each participant's own least-squares line; "
            "dashed: the common within-participant slope (r_rm). speed_accuracy.csv, speed_accuracy_model.csv and "
            "speed_accuracy_slopes.csv have every number.</p>")


_READING = {"phases": "rise time / RMSE after reach", "cue": "TCT / RMSE from the cue",
            "first_contact": "TCT / RMSE from first contact", "censored": "every trial, failure at the cap",
            "successful": "successful trials only", "time_to_event": "time to event (Cox HR ON : OFF)"}
#: The error window's readings (the same keys as two of the trade's).
_WINDOW = {"cue": "from the cue", "first_contact": "from first contact"}
_BLOCKS = {"error window": "The error window of RMSE and Max AE (Hodges–Lehmann shift ON − OFF [CI], Holm within "
                           "the window)",
           "TCT reading": "The reading of TCT (HL shift ON − OFF [CI] with Holm's p in the reading's family; the "
                          "hazard ratio of success ON : OFF [CI])",
           "speed-accuracy": "The speed–accuracy reading (r_rm [CI]; a trade only under the first, where the cue "
                             "reading agrees)"}


def sensitivity_html(within: Any, options: MetricOptions, metrics: Sequence[Metric], confidence: float = 0.95) -> str:
    """The headline results under every reading side by side, a block per choice; a differing conclusion flagged."""
    sens = within.sensitivity
    tables = []
    for analysis, block in sens.groupby("analysis", sort=False):
        readings = list(dict.fromkeys(block["reading"]))
        mine = {w for w in readings if block.loc[block["reading"] == w, "default"].any()}
        names = _WINDOW if analysis == "error window" else _READING
        head = "".join(f"<th>{html.escape(names.get(w, w))}{' (this report)' if w in mine else ''}</th>"
                       for w in readings)
        body = []
        for measure, g in block.groupby("measure", sort=False):
            g = g.set_index("reading")
            label = (codebook.label("participants.csv", codebook.exported_name(measure)) if analysis != "speed-accuracy"
                     else f"r_rm, {_MODE[measure.split()[-1]]}")
            cells = []
            for w in readings:
                if w not in g.index:
                    cells.append("<td></td>")
                    continue
                r = g.loc[w]
                holm = math.isfinite(float(r["p_holm"]))
                shown = fmt_p(r["p_holm"] if holm else r["p_value"])  # "&lt; 0.0001" carries its own sign
                p = f"p{' (Holm)' if holm else ''} {shown if shown.startswith('&lt;') else '= ' + shown}"
                cells.append(f"<td class=\"wrap\">{fmt(r['estimate'])} {_ci(r['ci_low'], r['ci_high'])}, {p}, "
                             f"n = {int(r['n'])}<br><i>{html.escape(str(r['conclusion']))}</i></td>")
            differs = bool(g["differs"].any())
            flag = '<td class="flag">differs</td>' if differs else "<td>same</td>"
            cls = ' class="differs"' if differs else ""
            body.append(f'<tr{cls}><td class="m">{html.escape(label)}</td>{"".join(cells)}{flag}</tr>')
        level = f"[{confidence * 100:g} % CI]"  # the level the intervals were computed at
        caption = html.escape(_BLOCKS[analysis].replace("[CI]", level))
        tables.append(f'<div class="scroll"><table class="within sens"><caption>{caption}'
                      f"</caption><thead><tr><th>measure</th>{head}<th>conclusion</th></tr></thead>"
                      f'<tbody>{"".join(body)}</tbody></table></div>')
    n_diff = sens.drop_duplicates(["analysis", "measure"])["differs"].sum()
    verdict = (f'<p class="warn">{plural(int(n_diff), "conclusion")} {"differs" if n_diff == 1 else "differ"} '
               "between the readings (flagged): report the reading with the result.</p>" if n_diff else
               "<p>Every conclusion is the same under every reading.</p>")
    return (f"<h3>Does a choice of the analysis change the answer?</h3><p>{windowed_words(metrics)} depend on the "
            f"window they are taken over, TCT on how a failed trial enters it, and the speed–accuracy association on "
            f"how speed and accuracy are measured. {window_fact(within, options)} Each choice's readings side by side "
            f"(sensitivity.csv), conclusions at p &lt; {ALPHA:g}; the report's own reading is marked.</p>{verdict}"
            + "".join(tables))


def window_fact(within: Any, options: MetricOptions) -> str:
    """What the window does to Max AE in this study, in numbers."""
    approach, n = within.max_ae_approach
    if not n:
        return ""
    return (f"From the cue, Max AE is the approach in {approach} of {plural(n, 'trial')} ({approach / n:.0%}): the "
            "largest error comes before first contact (at the cue the force is 0 N, an error of the whole target "
            "force), not from a peak force excursion; from first contact it never is.")


def secondary_html(within: Any, tables: dict[str, pd.DataFrame], png: bytes, target_order: list[str],
                   confidence: float = 0.95) -> str:
    """Learning and order, labelled as a secondary analysis; a plain statement where n is too small."""
    from analysis.stats.models import fixed_effects

    labels = {"intercept": "intercept (OFF, first target, trial 0)", "haptics_on": "haptics ON − OFF",
              "trial_number": "per trial (learning)"}
    for t in target_order[1:]:
        labels[f"target_{t}"] = f"{t} − {target_order[0]}"
        labels[f"haptics_on_x_target_{t}"] = f"ON × {t}"
    fe = fixed_effects(within.learning)
    too_few = [f for f in within.learning if not f.fitted]
    plain = (f'<p class="warn">{html.escape(too_few[0].note[0].upper() + too_few[0].note[1:])}: the learning models '
             "are not fitted; the figure below is descriptive only.</p>" if too_few else "")
    order = within.order
    rows = "".join(
        f"<tr><td class=\"m\">{html.escape(codebook.label('participants.csv', codebook.exported_name(r.metric)))}"
        f"</td><td>{int(r.n_on_first)}</td><td>{int(r.n_off_first)}</td><td>{fmt(r.median_diff_on_first, 4)}</td>"
        f"<td>{fmt(r.median_diff_off_first, 4)}</td><td>{fmt(r.u_statistic, 1)}</td><td>{fmt_p(r.p_value)}</td>"
        f"<td class=\"wrap\">{html.escape(str(r.note))}</td></tr>" for r in order.itertuples())
    order_plain = ""
    if not order["computable"].any():
        why = str(order["note"].iloc[0]).removeprefix("not tested: ")
        order_plain = f'<p class="warn">The order check is not tested: {html.escape(why)}.</p>'
    return ("<h2>Secondary analysis: learning and order</h2><p><i>A secondary analysis, not part of the paper's "
            "tests:</i> did participants improve over the session, and does the effect of feedback depend on the "
            f"mode met first? Trial-level models per outcome (participant as the unit).</p>{plain}"
            + (_model_table(fe, labels, "metric ~ mode × target + trial number + (1 | participant); success: logistic "
                            "GEE, estimates in log-odds", confidence) if not too_few else "")
            + f"<figure>{img(png, 'each metric over the trials of the session by mode')}</figure>"
            f"<h3>Order</h3>{order_plain}<div class=\"scroll\"><table class=\"within\"><caption>ON − OFF per "
            "participant, ON-first against OFF-first participants (first trial of the stored schedule), Mann–Whitney U"
            "</caption><thead><tr><th>measure</th><th>ON first</th><th>OFF first</th><th>median ON − OFF, ON first"
            "</th><th>median ON − OFF, OFF first</th><th>U</th><th>p</th><th>note</th></tr></thead>"
            f"<tbody>{rows}</tbody></table></div>")


def incomplete_html(within: Any, included: bool) -> str:
    """The incomplete experiment sessions, each with its reason, and whether they are analysed."""
    inc = within.incomplete
    if inc.empty:
        res = within.resumed
        res = res[res["kind"] == "experiment"].drop_duplicates(["database", "session_id"])
        after = (f" ({len(res)} of them after an interruption: see Interrupted and resumed sessions)"
                 if len(res) else "")
        return f"<p>Every experiment session completed{after}.</p>"
    their = "its" if len(inc) == 1 else "their"
    how = (f"analysed with {their} finished trials (report --include-incomplete)" if included else
           f"left out of every analysis (the default; report --include-incomplete analyses {their} finished trials)")
    items = "".join(f"<li>{html.escape(str(r))}</li>" for r in inc["reason"])
    return (f"<h3>Incomplete sessions</h3><p>{plural(len(inc), 'experiment session')} did not complete, {how}:</p>"
            f"<ul>{items}</ul>")


def resumed_html(within: Any) -> str:
    """Every session interrupted and resumed: when, which trial the interruption cut, the break where known."""
    res = within.resumed
    if res.empty:
        return "<h3>Interrupted and resumed sessions</h3><p>None: every session ran in one go.</p>"
    n = res.drop_duplicates(["database", "session_id"]).shape[0]
    items = "".join(f"<li>{html.escape(str(r))}</li>" for r in res["reason"])
    return (f"<h3>Interrupted and resumed sessions</h3><p>{plural(n, 'session')} {'was' if n == 1 else 'were'} "
            f"interrupted and resumed ({plural(len(res), 'resume')}; sessions.csv counts each session's runs, "
            "n_runs). The trial an interruption cut is stored as aborted (interrupted) and counted under Trials "
            f"that did not count; the session clock goes on from the last stored moment:</p><ul>{items}</ul>")


def deviations_html(within: Any) -> str:
    """Every recorded deviation from the protocol (events of a deviation kind), or a line saying there were none."""
    dev = within.deviations
    if dev.empty:
        return "<h3>Deviations from the protocol</h3><p>None recorded.</p>"
    return ("<h3>Deviations from the protocol</h3><p>Recorded during the sessions (deviations.csv):</p>"
            + html_table(dev, "deviations.csv"))


def provenance_html(within: Any) -> str:
    """Which code ran the sessions, with its warnings."""
    rows = "".join(f"<tr><td class=\"m\">{html.escape(r.code)}</td><td>{int(r.n_sessions)}</td>"
                   f"<td class=\"wrap\">{html.escape(r.sessions)}</td></tr>" for r in within.provenance.itertuples())
    warn = "".join(f'<p class="warn">{html.escape(w)}</p>' for w in within.provenance_warnings)
    return (f"<p>Which code ran the sessions (package version, git commit of the checkout, uncommitted changes):</p>"
            f'{warn}<div class="scroll"><table><thead><tr><th>code</th><th>sessions</th><th>which</th></tr></thead>'
            f"<tbody>{rows}</tbody></table></div>")


def top_warnings(within: Any, included: bool) -> str:
    """The warnings the page opens with: different code, incomplete sessions, window-dependent conclusions."""
    out = [w for w in within.provenance_warnings
           if w.startswith(("The sessions of this study ran different code", "The analysed sessions ran under",
                            "Participant numbers repeat"))]
    inc = within.incomplete
    if len(inc):
        are = "is" if len(inc) == 1 else "are"
        out.append(f"{plural(len(inc), 'experiment session')} did not complete and "
                   f"{are} {'analysed (--include-incomplete)' if included else 'left out'}; see What was delivered.")
    n_dmg = len(within.damaged)
    if n_dmg:
        out.append(f"{plural(n_dmg, 'trial')} left out: {'its' if n_dmg == 1 else 'their'} recording is damaged; "
                   "see Trials that did not count.")
    n_diff = int(within.sensitivity.drop_duplicates(["analysis", "measure"])["differs"].sum())
    if n_diff:
        out.append(f"{plural(n_diff, 'conclusion')} depend{'s' if n_diff == 1 else ''} on a choice of the analysis "
                   "(the error window, the TCT reading or the speed–accuracy reading); see the sensitivity table.")
    uneven = within.unbalanced
    if len(uneven):
        out.append(f"{plural(len(uneven), 'participant × mode')} {'has' if len(uneven) == 1 else 'have'} trials "
                   "spread unequally over the targets (" + "; ".join(
                       f"{r.participant_code} {str(r.haptic_mode).upper()}: {r.counts}" for r in uneven.itertuples())
                   + "): each such mode's values are the mean of the per-target values, every target weighing the "
                   "same (participants.csv, targets_balanced).")
    return "".join(f'<p class="warn">{html.escape(w)}</p>' for w in out)


def _gee_words(metrics: Sequence[Metric]) -> str:
    """The learning models' words for a yes/no outcome of the study, if it has one ("" otherwise)."""
    yes_no = [m.name for m in tested(metrics) if m.boolean]
    return (", a logistic GEE with an exchangeable working correlation within a participant and Mancl and DeRouen's "
            "bias-reduced sandwich standard errors (the plain sandwich is too small with few clusters) for "
            f"{listed(yes_no)}" if yes_no else "")


def methods_within(within: Any, options: MetricOptions, confidence: float, metrics: Sequence[Metric]) -> str:
    """The methods sentences of the within-participant analyses (the trade, the windows, learning and order)."""
    fitted = all(f.fitted for f in within.learning)
    learning_n = ("" if fitted else f" With fewer than {MIN_PARTICIPANTS} participants the models are not fitted "
                  "and the section says so.")
    return (
        "<p><b>Speed–accuracy trade.</b> Speed is each trial's rise time, from first contact (task force above "
        "the contact threshold) to the first sample at or above the band's lower edge; accuracy is the RMSE of the "
        "task force against F* over the fixed 1 s from that sample (registry metrics rise_time_s and reach_rmse_n). "
        "The two windows do not overlap and the accuracy window has the same length in every trial, so neither "
        "measure holds the other (docs/science.md §6.1; a null model of participants whose accuracy is independent "
        "of their speed shows no trade in the tests). Every trial with both counts, failed or not. Their "
        "within-participant association is the repeated-measures correlation r_rm (Bakdash &amp; Marusich 2017), "
        "per mode and over both modes with each participant × mode as its own group: the correlation of the "
        "participant-centred values, with N − k − 1 degrees of freedom (N trials, k groups), the p-value of the "
        "common slope's t test, as the rmcorr R package computes them, and a "
        f"{confidence:.0%} Fisher-z interval of r_rm as a partial correlation, SE = 1/√(df − 1), as pingouin's rm_corr "
        "computes it; an r_rm within 10<sup>−12</sup> of ±1 (a perfect line, whose last digit depends on "
        "the computer's arithmetic) is reported as ±1 with p = 0 on every computer. It is called a trade only where "
        "that interval lies below zero and the cue reading "
        "(TCT of the successful trials against RMSE from the cue, the report's reading before this one, kept as a "
        "sensitivity with the first-contact one) also does. A linear mixed model rise time ~ RMSE after reach × mode "
        "with a random intercept and a random slope of mode per participant (and a fixed effect per site) "
        "(statsmodels MixedLM, REML; Powell's method, then L-BFGS) gives the slope with haptics OFF and its "
        "ON − OFF difference, with Wald intervals. Each participant's own least-squares line is drawn; no "
        "pooled-trial p-value is computed.</p>"
        "<p><b>Sensitivity.</b> Every analysis uses the window and TCT reading named in the header; the "
        f"sensitivity table repeats the primary ON-vs-OFF tests with {windowed_words(metrics)} from the cue and from "
        "first contact (Holm within each window), TCT's test in both readings with the Cox model's hazard ratio, and "
        f"r_rm in every speed–accuracy reading, and flags each conclusion (at p &lt; {ALPHA:g}) that differs.</p>"
        "<p><b>Secondary analysis: learning and order.</b> Per outcome, a trial-level model with haptic mode, "
        "target, their interaction and the trial's number in the session (its position, aborted trials counted) "
        "(and a site term where sites were pooled) as fixed effects and participant as the unit: linear mixed "
        "models with a random intercept and a random slope of mode per participant (REML; the intercept alone, "
        "said in the note, where the slope cannot be fitted) for "
        f"{listed([m.short for m in tested(metrics) if not m.boolean])}{_gee_words(metrics)} (statsmodels); the "
        "trial-number coefficient is the "
        "change per trial. "
        "Order: each participant's ON − OFF difference compared between participants whose stored schedule "
        "began with an ON trial and those whose began with an OFF trial (two-sided Mann–Whitney U; not tested "
        f"with fewer than {MIN_ORDER_GROUP} in a group).{learning_n} These tests are exploratory and are not "
        "corrected for multiplicity.</p>"
    )
