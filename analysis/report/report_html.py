"""The report's page: report.html, self-contained (figures embedded), readable on screen and on paper.

:func:`page` renders the computed study and the exported tables
(:mod:`analysis.report.report_tables`); it computes nothing of its own.
"""

from __future__ import annotations

import datetime as dt
import functools
import html
import os
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pandas as pd

from analysis.reading import codebook
from analysis.reading.load import StudyData
from analysis.reading.metrics import MetricOptions, TrialTable
from analysis.report import report_design, report_sections, report_tct
from analysis.report.html_parts import fmt as _fmt
from analysis.report.html_parts import fmt_p, fmt_w, part_banner, part_title, plural
from analysis.report.html_parts import html_table as _html_table
from analysis.report.html_parts import img as _img
from analysis.report.html_parts import th as _th
from analysis.report.latency_methods import latency_paragraph, qualification_paragraph
from analysis.report.measures import figure_groups, mean_words, secondary, secondary_note, windowed_words
from analysis.stats.aggregate import mean_sd
from analysis.stats.loop_health import ABORT_CAUSE_TEXT, LOOP_BOUNDS, abort_counts
from analysis.stats.wilcoxon import methods_text
from foundation.version import software_provenance
from protocol.metrics import Metric, family_word, primary
from protocol.runner.study_rules import FAULT_REHEARSAL_EVENT
from protocol.tasks.window import CONTACT_THRESHOLD_N

__all__ = ["DAMAGED_TEXT", "page", "plural"]

#: How a trial left out for a damaged recording reads in the table of trials that did not count.
DAMAGED_TEXT = "recording damaged (the trial ended, but its records touch a damaged block: not analysed)"

#: The Wilcoxon table on the page (``hl`` is the Hodges–Lehmann estimate with its interval).
_STAT_HTML_COLUMNS = ("metric", "n", "n_zero", "n_ties", "median_off", "median_on", "hl", "statistic", "method",
                      "p_value", "p_holm", "rank_biserial", "r")



def _measure_label(metric: str) -> str:
    """``rmse_N`` → ``RMSE (N)``: the heading the participants table gives the measure."""
    return codebook.label("participants.csv", metric)


def _with_interval(v: float, row: pd.Series) -> str:
    """A rank-biserial r with its interval where the row has one."""
    lo, hi = row.get("rank_biserial_ci_low", np.nan), row.get("rank_biserial_ci_high", np.nan)
    return _fmt(v) + (f" [{_fmt(lo)}, {_fmt(hi)}]" if np.isfinite(lo) else "")


def _stats_html(frame: pd.DataFrame, file: str, metrics: Sequence[Metric], lead: Sequence[str] = (),
                caption: str = "") -> str:
    """A test table for the page: the HL estimate and interval in one column; each distinct note once, numbered.

    W is shown with the precision it has (a rank sum: whole or half), p-values to 3 significant digits; each
    note is the one of its own row (it speaks of that row's pairs).
    """
    notes: dict[str, int] = {}
    cols = list(lead) + list(_STAT_HTML_COLUMNS)
    head = "".join(
        "<th title=\"Hodges–Lehmann estimate of the shift ON − OFF with its confidence interval\">HL shift ON − OFF "
        "[CI]</th>" if c == "hl" else _th(file, c) for c in cols
    )
    body = []
    secondaries = {m.participant_exported for m in secondary(metrics)}
    for _, row in frame.iterrows():
        label = html.escape(_measure_label(str(row["metric"])))
        for note in (row.get("note"), secondary_note(metrics) if row["metric"] in secondaries else ""):
            if isinstance(note, str) and note:  # the row's own note; a secondary measure's why, beside its p
                k = notes.setdefault(note, len(notes) + 1)
                label += f" <sup>{k}</sup>"
        e, lo, hi = row["hl_estimate"], row["hl_ci_low"], row["hl_ci_high"]
        hl = f"{_fmt(e)} [{_fmt(lo)}, {_fmt(hi)}]" if np.isfinite(e) else "–"
        special: dict[str, Callable[[Any], str]] = {"statistic": fmt_w, "p_value": fmt_p, "p_holm": fmt_p,
                   "rank_biserial": functools.partial(_with_interval, row=row)}
        cells = "".join(f"<td class=\"m\">{label}</td>" if c == "metric" else f"<td>{hl}</td>" if c == "hl" else
                        f"<td>{special[c](row.get(c)) if c in special else _fmt(row[c])}</td>" for c in cols)
        cls = ' class="nc"' if not bool(row["computable"]) else ""
        body.append(f"<tr{cls}>{cells}</tr>")
    foot = "".join(f"<li>{html.escape(n)}</li>" for n in notes)
    cap = f"<caption>{caption}</caption>" if caption else ""
    return (f'<div class="scroll"><table class="stats">{cap}<thead><tr>{head}</tr></thead><tbody>{"".join(body)}'
            f'</tbody></table></div>' + (f'<ol class="notes">{foot}</ol>' if foot else ""))


def _bar_figures(pngs: dict[str, bytes], metrics: Sequence[Metric]) -> str:
    """The bar figures, one per figure of the study's metrics (:func:`analysis.report.measures.figure_groups`)."""
    caption = ('<p class="caption">Bars: median across participants, whiskers: interquartile range (the tests are '
               "on medians; the data are skewed); dots: participants; n under each bar: participants with a value; "
               "marks: Wilcoxon p after Holm's correction (n.s. not significant, n/c not computable).</p>")
    return "\n".join(f"<figure><h2>{html.escape(g.heading)}</h2>{caption if i == 0 else ''}"
                     f"{_img(pngs[g.key], g.alt)}</figure>" for i, g in enumerate(figure_groups(metrics)))


def _secondary_definitions(metrics: Sequence[Metric]) -> str:
    """The secondary measures' definitions, for the methods ("" when there is none)."""
    return "".join(f" {html.escape(m.short[:1].upper() + m.short[1:])} ({html.escape(m.unit)}) is the "
                   f"{html.escape(m.description)}." for m in secondary(metrics))


def _deviations_methods(within: Any) -> str:
    """The methods' sentence on recorded deviations from the protocol: none, or each with its participant."""
    every = within.deviations
    rehearsed = every[every["kind"] == FAULT_REHEARSAL_EVENT]
    dev = every[every["kind"] != FAULT_REHEARSAL_EVENT]
    said = _rehearsals_methods(rehearsed)
    if dev.empty:
        return ("No deviation from the protocol was recorded (events of kind deviation or calibration_override)."
                + said)
    items = "; ".join(f"{html.escape(str(r.participant_code))}: {html.escape(str(r.detail).rstrip('. '))}"
                      for r in dev.head(5).itertuples())
    if len(dev) > 5:
        items += f"; and {len(dev) - 5} more"
    return (f"{plural(len(dev), 'deviation')} from the protocol {'was' if len(dev) == 1 else 'were'} recorded "
            f"(listed under Deviations from the protocol, deviations.csv; the trials they concern are analysed "
            f"as recorded): {items}." + said)


def _rehearsals_methods(rehearsed: Any) -> str:
    """The methods' sentence on faults rehearsed on the simulated rig ("" when none): counted by plan, not event."""
    if rehearsed.empty:
        return ""
    plans = {(r.participant_code, r.session_id, str(r.detail).split(": ", 1)[0]) for r in rehearsed.itertuples()}
    return (f" Faults were rehearsed on the simulated rig: {plural(len(plans), 'planned fault')} "
            f"({plural(len(rehearsed), 'event')} of kind fault_rehearsal under Deviations from the protocol: when "
            "each was planned and what it did); a trial a rehearsed fault aborted is left out like any aborted "
            "trial (Trials that did not count) and is no device's failure.")


def _data_methods(study: StudyData, table: TrialTable, excluded: dict[str, int], n_participants: int,
                  within: Any) -> str:
    """The data paragraph: what was analysed and what was left out, true whether or not incomplete sessions are in."""
    exp = study.sessions[study.sessions["kind"] == "experiment"]
    inc = within.incomplete
    reasons = "; ".join(html.escape(str(r)) for r in inc["reason"])
    are = "is" if len(inc) == 1 else "are"
    if inc.empty:
        incomplete = ("Every experiment session completed (one that did not would be left out and listed with its "
                      "reason; report --include-incomplete analyses its finished trials).")
    elif study.include_incomplete:
        incomplete = (f"{plural(len(inc), 'experiment session')} did not complete and {are} analysed with "
                      f"{'its' if len(inc) == 1 else 'their'} finished trials (report --include-incomplete): "
                      f"{reasons}.")
    else:
        incomplete = (f"{plural(len(inc), 'experiment session')} did not complete and {are} left out with "
                      f"{'its' if len(inc) == 1 else 'their'} "
                      f"{plural(excluded['incomplete_trials'], 'finished trial')} (the default; report "
                      f"--include-incomplete analyses them): {reasons}.")
    res = within.resumed
    if len(res):
        n_res = res.drop_duplicates(["database", "session_id"]).shape[0]
        incomplete += (f" {plural(n_res, 'session')} {'was' if n_res == 1 else 'were'} interrupted and resumed, "
                       "analysed as one session each, the trial an interruption cut stored as aborted (listed "
                       "under What was delivered): " + "; ".join(
                           f"{html.escape(str(r.participant_code))}, session {r.session_id}, run {r.run} from "
                           f"{r.resumed_at_s:.3f} s" + ("" if pd.isna(r.cut_trial) else f" (cut trial {r.cut_trial})")
                           for r in res.itertuples()) + ".")
    n_ab, n_rerun = within.reruns
    if n_ab == 0:
        aborted = "no aborted trial"
    elif n_rerun == n_ab:
        aborted = f"{plural(n_ab, 'aborted trial')} (each re-run later in its session)"
    elif n_rerun == 0:
        aborted = f"{plural(n_ab, 'aborted trial')} ({'not' if n_ab == 1 else 'none'} re-run in its session)"
    else:
        aborted = (f"{plural(n_ab, 'aborted trial')} ({n_rerun} of them re-run later in their session; the other "
                   f"{n_ab - n_rerun} not)")
    dmg = within.damaged
    damaged = ("" if dmg.empty else
               f" and {plural(len(dmg), 'trial')} whose recording is damaged (listed under Trials that did not count; "
               "the tests are computed without "
               f"{'it' if len(dmg) == 1 else 'them'}): " + "; ".join(html.escape(str(r)) for r in dmg["reason"]))
    codes = "; ".join(f"{html.escape(r.code)} ({plural(int(r.n_sessions), 'session')})"
                      for r in within.provenance.itertuples())
    dbs = ", ".join(html.escape(os.path.basename(d)) for d in study.databases)
    check = (f"All {plural(table.n_from_samples, 'analysed trial')} were recomputed from their stored 1 kHz samples"
             + (" and agree with the values stored live" if table.n_disagree == 0 else
                f"; {table.n_disagree} disagree with the values stored live (the recomputed values are used)")
             + (f"; {plural(table.n_stored_only, 'trial')} without samples use their stored values"
                if table.n_stored_only else "")
             + ".")
    return (f"<p><b>Data.</b> {plural(n_participants, 'participant')} in "
            f"{plural(int(exp['analysed'].sum()), 'analysed experiment session')} of {len(exp)} from "
            f"{plural(len(study.databases), 'database')} ({dbs}), {plural(len(study.included), 'analysed trial')}. "
            f"{_origin(study)[1]} {incomplete} Excluded: "
            f"{plural(excluded['training_sessions'], 'training session')} "
            f"({plural(excluded['training_trials'], 'trial')}){',' if damaged else ' and'} {aborted}{damaged}. "
            f"{_deviations_methods(within)} "
            f"Recorded with haptic-study {codes}; "
            f"analysed with haptic-study {html.escape(software_provenance().describe())}. {check}</p>")


def _task_methods(study: StudyData, caps: list[float]) -> str:
    """The analysed sessions' tasks' own definitions (their rules, with their parameters), each kind once."""
    keys = study.included[["database", "session_id"]].drop_duplicates()
    tasks = [study.task_of(db, sid) for db, sid in zip(keys["database"], keys["session_id"], strict=True)]
    return " ".join(kind.methods([t for t in tasks if type(t) is kind], caps)
                    for kind in dict.fromkeys(type(t) for t in tasks))


def _methods(study: StudyData, table: TrialTable, options: MetricOptions, zero_method: str, confidence: float,
             excluded: dict[str, int], n_participants: int, within: Any) -> str:
    trials = study.included
    metrics = study.metrics
    family = [m.participant for m in primary(metrics)]
    cap = sorted(set(trials["max_trial_s"]))
    targets = (trials.drop_duplicates("target_label").sort_values("target_force_n")[["target_label", "target_force_n"]])
    target_txt = ", ".join(f"{lab} {f:g} N"
                           for lab, f in zip(targets["target_label"], targets["target_force_n"], strict=True))

    def one(vals: list[float], unit: str) -> str:
        return " / ".join(f"{v:g}{unit}" for v in vals)

    window = ("from the cue to the trial end, the approach before contact included (error window: cue, "
              "the default, the paper's \"during the trial\")"
              if options.error_window == "cue" else
              f"from first contact (the first sample with task force above {CONTACT_THRESHOLD_N:g} N) to the "
              "trial end; a trial without contact has no RMSE or Max AE (error window: first_contact)")
    tct = ("averaged over successful trials only, so it is undefined for a participant with no success in a mode "
           "(that participant's pair is left out of the TCT test and counted)"
           if options.tct_policy == "successful" else
           f"averaged over all trials, a failed trial counting as the trial cap ({one(cap, ' s')})")
    design = (report_design.training_methods(study) + report_design.feedback_methods(study)
              + report_design.sites_methods(study))
    return (
        _data_methods(study, table, excluded, n_participants, within) + design
        + f"<p><b>Trial metrics.</b> Targets: {html.escape(target_txt)}. The task force is the magnitude of the "
        f"filtered, gravity- and bias-compensated contact force. {html.escape(_task_methods(study, cap))} "
        f"{windowed_words(metrics)} "
        f"of F against F* are taken {window}. Time in band is the number of in-band samples times 1 ms; peak force "
        f"is the largest task force in the window.{_secondary_definitions(metrics)} These are the definitions of "
        "protocol.metrics, the same code that judged the trials live. "
        f"{report_sections.window_fact(within, options)}</p>"
        f"<p><b>Aggregation.</b> For each participant and haptic mode, the success rate is successes / trials and "
        f"{mean_words(metrics)} are means over trials; TCT is {tct}. A participant × mode whose trials are not spread "
        f"equally over the targets (an incomplete session analysed) has the mean of its per-target values, each "
        f"target weighing the same. Across participants, the bars and the headline show the median with its "
        f"interquartile range, the summary the Wilcoxon test is about (the headline gives the mean ± SD (n − 1) "
        f"beside it, as <code>haptic-study run</code> prints it), and the dots are participants. "
        f"Trials are numbered from 1 in every table and figure (the database's trial_index + 1); every column of "
        f"every CSV file is described, with its unit, in codebook.csv.</p>"
        f"<p><b>Tests.</b> {html.escape(methods_text(zero_method, confidence))} Holm's step-down correction is "
        f"applied across the {len(family)} outcome measures "
        f"({', '.join(codebook.exported_name(m) for m in family)}), and separately "
        f"within each target; significance marks in the figures use the Holm-adjusted p-values "
        f"(* p &lt; 0.05, ** p &lt; 0.01, *** p &lt; 0.001, n/c not computable). "
        f"{html.escape(secondary_note(metrics))}{' Its mark uses its own p. ' if secondary(metrics) else ''}"
        "No p-value in this report comes from trials pooled as if independent.</p>"
        + (report_tct.tct_methods(within, options, confidence) if any(m.success_only for m in metrics) else "")
        + report_sections.methods_within(within, options, confidence, metrics)
        + latency_paragraph(study)
        + qualification_paragraph(study)
    )


_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;
color:#222;line-height:1.45}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ddd;padding-bottom:.2em;margin-top:1.8em}
.meta{color:#666;font-size:.9em}table{border-collapse:collapse;margin:.6em 0 1.2em;font-size:.85em}
th,td{border:1px solid #ddd;padding:3px 7px;text-align:right}td{white-space:nowrap}
th{background:#f4f4f4;vertical-align:bottom}
td:first-child,th:first-child,td.m{text-align:left}figure{margin:0;break-inside:avoid}
tr.nc td{color:#999;font-style:italic}
img{max-width:100%;height:auto;display:block;margin:.5em 0}
.key{display:grid;grid-template-columns:repeat(auto-fit,minmax(200px,1fr));gap:.6em;margin:1em 0}
.key div{background:#f7f9fc;border:1px solid #e3e8f0;border-radius:6px;padding:.6em .8em}
.key b{display:block;font-size:1.25em}.key small{color:#555}.scroll{overflow-x:auto}.notes{font-size:.85em;color:#555}
.warn{background:#fff4e5;border:1px solid #f0c36d;padding:.5em .8em;border-radius:6px}
.origin{padding:.5em .8em;border-radius:6px;font-weight:600}.origin.sim{background:#eef3ff;border:1px solid #9db4e8}
.origin.real{background:#eefaf0;border:1px solid #9ed3a8}.origin.mixed{background:#fff4e5;border:1px solid #f0c36d}
.caption{font-size:.85em;color:#555;margin:.2em 0 .8em}td.wrap{white-space:normal;text-align:left;min-width:12em}
table caption{caption-side:top;text-align:left;color:#555;padding:0 0 .2em}
td.flag{color:#b00020;font-weight:600}tr.differs td{background:#fff4e5}
table.power caption{caption-side:top;text-align:left;font-size:1.05em;color:#555;padding:0 0 .3em}
table.power th{white-space:nowrap}table.power tr.family td{background:#fafafa}
@page{size:A4;margin:12mm}
@media print{
 body{max-width:none;margin:0;padding:0;font-size:9.5pt;line-height:1.3}
 .scroll{overflow:visible}
 table{font-size:7pt;margin:.3em 0 .8em;page-break-inside:auto}
 th,td{padding:1px 3px}th{white-space:normal}td{white-space:nowrap}td.wrap{white-space:normal}
 tr,img,.key div{page-break-inside:avoid;break-inside:avoid}
 thead{display:table-header-group}
 h2,h3{page-break-after:avoid;break-after:avoid}
 .power-head{break-inside:avoid;page-break-inside:avoid;break-after:avoid;page-break-after:avoid}
 .power-head+.scroll table{break-before:avoid;page-break-before:avoid}
 table.power caption,table.power thead{break-after:avoid;page-break-after:avoid}
 table.power tbody tr:nth-child(-n+3){break-before:avoid;page-break-before:avoid}
 .key{grid-template-columns:repeat(4,1fr)}
 img{max-width:100%;max-height:120mm;width:auto}
 a{color:inherit;text-decoration:none}
}
"""


def _origin(study: StudyData) -> tuple[str, str]:
    """(CSS class, sentence) saying whether the analysed data come from the simulated rig or the real one."""
    exp = study.sessions[study.sessions["kind"] == "experiment"]
    rigs = exp["rig"].value_counts()
    n_sim, n_real = int(rigs.get("sim", 0)), int(rigs.get("real", 0))
    chosen = sorted({str(s) for s in exp.get("pipeline_settings", pd.Series(dtype=str)) if s and str(s) != "nan"})
    settings = (f" Pipeline settings not the paper's (run --set): {' / '.join(chosen)}." if chosen else "")
    if n_real == 0:
        return "sim", ("Simulated data: every experiment session was recorded on the simulated rig (rig = sim) with "
                       "simulated participants. These numbers describe the simulation, not people." + settings)
    if n_sim == 0:
        return "real", "Recorded on the real rig (rig = real) with real participants." + settings
    return "mixed", (f"Mixed data: {plural(n_sim, 'experiment session')} on the simulated rig (rig = sim) and "
                     f"{n_real} on the real rig (rig = real); see the sessions table." + settings)


def _headline(per: pd.DataFrame, stats: pd.DataFrame, marks: dict[str, str], metrics: Sequence[Metric]) -> str:
    """One card per primary measure of the study: the median [IQR] across participants OFF → ON (what the test is
    about), the mean ± SD beside it (what the paper's figures show), and the Holm-adjusted test."""
    by_metric = stats.set_index("metric")
    cards = []
    for m in (p.participant for p in primary(metrics)):
        name = codebook.exported_name(m)
        parts, iqr, means, ns = [], [], [], []
        for mode in ("off", "on"):
            v = per.loc[per["haptic_mode"] == mode, name].to_numpy(dtype=float)
            v = v[np.isfinite(v)]
            mean, sd, n = mean_sd(v)
            q1, med, q3 = (np.percentile(v, (25, 50, 75)) if n else (np.nan,) * 3)
            parts.append(_fmt(med))
            iqr.append(f"[{_fmt(q1)}, {_fmt(q3)}]" if n > 1 else "[one value]")
            means.append(_fmt(mean) + (f" ± {_fmt(sd)}" if n > 1 else ""))  # one participant: no spread, no ±
            ns.append(n)
        who = plural(ns[0], "participant") if ns[0] == ns[1] else f"{ns[0]} (OFF) / {ns[1]} (ON) participants"
        p_holm = by_metric.at[name, "p_holm"]
        n_test = by_metric.at[name, "n"]  # the ranked pairs: zero differences and missing sides left out
        test = (f"Wilcoxon n = {int(n_test)}, p (Holm) = {fmt_p(p_holm)}, {html.escape(marks.get(m, ''))}"
                if np.isfinite(p_holm) else "Wilcoxon test not computable")
        spread = (f"median across {who}, IQR {iqr[0]} → {iqr[1]} (mean ± SD {means[0]} → {means[1]})"
                  if max(ns) > 1 else f"{who}: one value per mode, no spread")
        cards.append(f"<div>{html.escape(_measure_label(name))}<b>{parts[0]} → {parts[1]}</b>"
                     f"<small>OFF → ON, {spread}; {test}</small></div>")  # fmt_p escapes
    return f'<div class="key">{"".join(cards)}</div>'


def _record_html(study: StudyData, tables: dict[str, pd.DataFrame], within: Any) -> str:
    """Trials not counted (by cause) and the loop's health per participant, with the trials outside the bounds."""
    counts = abort_counts(study)
    damaged = within.damaged
    total = int(counts["n_trials"].sum()) + len(damaged)
    rows = "".join(f"<tr><td>{html.escape(ABORT_CAUSE_TEXT.get(c, c))}</td><td>{n}</td></tr>"
                   for c, n in zip(counts["abort_cause"], counts["n_trials"], strict=True))
    rows += f"<tr><td>{html.escape(DAMAGED_TEXT)}</td><td>{len(damaged)}</td></tr>"
    listed = ("" if damaged.empty else
              f'<p class="warn">{plural(len(damaged), "trial")} ran to {"its" if len(damaged) == 1 else "their"} '
              f"end but {'is' if len(damaged) == 1 else 'are'} left out: the records a trial's metrics are "
              "recomputed from touch a damaged block of the recording (haptic-study check names it), so they are "
              "not analysed from what is left:</p><ul>"
              + "".join(f"<li>{html.escape(str(r))}</li>" for r in damaged["reason"]) + "</ul>")
    aborted = (f"<p>{plural(total, 'experiment trial')} did not count (a trial aborted in a session that went on is "
               "re-run under the protocol's abort policy; see the methods for how many were), by cause:</p>"
               f'<div class="scroll"><table><thead><tr><th>cause</th><th>trials</th></tr></thead>'
               f"<tbody>{rows}</tbody></table></div>{listed}")
    health = tables["loop_health.csv"]
    recorded = health[health["within_bounds"].notna()]
    bounds = "; ".join(b.describe() for b in LOOP_BOUNDS)
    if recorded.empty:
        loop = "<p>No trial carries a loop-health record (databases of schema version 1).</p>"
    else:
        outside = recorded[~recorded["within_bounds"].astype(bool)]
        def counted(r: Any) -> str:
            return "" if r.outcome != "aborted" else f" (aborted: {r.abort_cause or 'cause not recorded'}; not counted)"

        listed = "".join(
            f"<li>{html.escape(str(r.participant_code))}, session {int(r.session_id)}, trial {int(r.trial_number)}"
            f"{html.escape(counted(r))}: {html.escape(str(r.outside_bounds))}</li>"
            for r in outside.head(20).itertuples())
        more = f"<li>… and {len(outside) - 20} more (loop_health.csv)</li>" if len(outside) > 20 else ""
        verdict = (f"<p>Every one of the {plural(len(recorded), 'trial')} with a loop record stayed within the "
                   "bounds.</p>" if outside.empty else
                   f'<p class="warn">{plural(len(outside), "trial")} of {len(recorded)} left the bounds:</p>'
                   f"<ul>{listed}{more}</ul>")
        loop = (_html_table(tables["loop_health_by_participant.csv"], "loop_health_by_participant.csv") + verdict)
    sessions = study.sessions
    virtual = int(((sessions["rig"] == "sim") & (sessions.get("clock", "") == "virtual")).sum())
    clock = ("" if not virtual else
             f"<p>On the virtual clock ({plural(virtual, 'session')} of the simulated rig run headless) computing "
             "takes no time: every period is exactly 1 ms and the latency is the sample's age. A session on the real "
             "clock (the GUI's, the real rig's) measures them in real time.</p>")
    return (f"<h2>What was delivered</h2>{report_sections.incomplete_html(within, study.include_incomplete)}"
            f"{report_sections.resumed_html(within)}{report_sections.deviations_html(within)}"
            f"<h3>Trials that did not count</h3>{aborted}"
            f"<h3>The 1 kHz loop, per trial</h3>"
            f"<p>Each trial records how the haptic loop ran during it. Bounds: {html.escape(bounds)}.</p>{clock}{loop}")


def _when(v: object) -> str:
    """An ISO 8601 time as ``YYYY-MM-DD HH:MM`` (UTC), for the page."""
    return "" if not isinstance(v, str) else html.escape(v[:16].replace("T", " "))


def _warnings(study: StudyData, table: TrialTable, stats: pd.DataFrame, within: Any) -> str:
    """The warnings the page opens with: disagreeing trials, tests not computable, and the record's."""
    warn = ""
    if table.n_disagree:
        warn = (f'<p class="warn">{plural(table.n_disagree, "trial")} disagree between the metrics stored live and '
                "those recomputed from samples; see the methods.</p>")
    nc = stats[~stats["computable"].astype(bool)]
    if len(nc):
        warn += ('<p class="warn">Not computable: '
                 + "; ".join(f"{html.escape(_measure_label(str(r.metric)))}: {html.escape(str(r.note))}"
                             for r in nc.itertuples()) + "</p>")
    return warn + report_sections.top_warnings(within, study.include_incomplete)


def _head_html(study: StudyData, table: TrialTable, options: MetricOptions, n_participants: int,
               tables: dict[str, pd.DataFrame], within: Any) -> str:
    """The page's head: title, what it covers and how it was made, where the data come from, and its warnings."""
    origin_class, origin_text = _origin(study)
    now = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    n_trials = len(tables["trials.csv"])
    tct = f" · TCT: {options.tct_policy}" if "time_to_event.csv" in tables else ""  # (a task that times no success)
    return f"""<h1>Haptic feedback study: report</h1>
<p class="meta">{plural(n_participants, 'participant')} · {plural(n_trials, 'trial')} · generated {now} by haptic-study
{html.escape(software_provenance().describe())} · error window: {options.error_window}{tct}
{'· incomplete sessions included' if study.include_incomplete else ''}</p>
<p class="origin {origin_class}">{html.escape(origin_text)}</p>
{_warnings(study, table, tables["stats.csv"], within)}"""


def _sessions_html(sess: pd.DataFrame, within: Any) -> str:
    """The sessions read: which code ran each, and the table of sessions.csv's main columns."""
    sess_cols = ["database", "session_id", "participant_code", "participant_number", "kind", "status", "rig", "seed",
                 "started_at", "n_runs", "n_trials", "trial_time_s", "live_force_aid", "software_version",
                 "software_commit", "software_dirty", "analysed"]
    if sess["site"].astype(str).str.len().any():
        sess_cols.insert(1, "site")
    short = {"started_at": _when, "ended_at": _when, "software_commit": report_sections.short_commit}
    return (f"<h2>Sessions</h2>\n{report_sections.provenance_html(within)}\n"
            f"{_html_table(sess, 'sessions.csv', sess_cols, cell=short)}")


#: The test table's lead, where the study has a secondary measure.
_SECONDARY_OWN = " (a secondary measure is tested on its own: see its note)"


def page(*, study: StudyData, table: TrialTable, options: MetricOptions, zero_method: str, confidence: float,
         excluded: dict[str, int], n_participants: int, n_incomplete: int, tables: dict[str, pd.DataFrame],
         marks_overall: dict[str, str], pngs: dict[str, bytes], examples: list[tuple[str, bytes]],
         power_html: str = "", within: Any = None, target_order: Sequence[str] = (), sections_html: str = "") -> str:
    """report.html: self-contained (figures embedded), readable on screen and on paper.

    Parameters
    ----------
    study, table, options, zero_method, confidence
        The study, its recomputed trials and the analysis choices (for the methods section).
    excluded, n_participants, n_incomplete
        What was left out, and how many participants and unfinished sessions there are.
    tables
        :func:`analysis.report.report_tables.export_tables`' result: the page shows the CSVs' rows.
    marks_overall, pngs, examples, power_html
        Significance marks, the figures (PNG bytes), the example trials' figures and the power section.
    sections_html
        The study's tasks' own sections (:mod:`analysis.report.task_sections`; "" when its tasks have none).
    within, target_order
        The within-participant analyses (``analysis.report.report._Within``) and the targets in order.

    Returns
    -------
    str
        The HTML document.
    """
    stats, per = tables["stats.csv"], tables["participants.csv"]
    win = report_sections.window_words(options.error_window)
    metrics = study.metrics
    timed = any(m.success_only for m in metrics)  # a task with a completion time: its TCT sections and the trade
    per_cols = ["participant_code", "participant_number", "haptic_mode",
                *(c for c in codebook.WIDE_MEASURES if c in per.columns)]  # the study's measures
    title = part_title(study.part, "haptic-study report")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title><style>{_CSS}</style></head><body>
{part_banner(study)}{_head_html(study, table, options, n_participants, tables, within)}
{_headline(per, stats, marks_overall, metrics)}
<h2>Haptics ON vs OFF</h2>
<p>Paired Wilcoxon signed-rank tests across participants (differences ON − OFF); p (Holm) is adjusted across the
{family_word(metrics)} primary measures{_SECONDARY_OWN if secondary(metrics) else ""}.
Medians are across participants; the HL shift is the Hodges–Lehmann estimate of ON − OFF with its
{confidence:.0%} confidence interval. Hover over a heading for its definition; codebook.csv has them all.</p>
{_stats_html(stats, "stats.csv", metrics, caption=f"ON vs OFF, all targets; {windowed_words(metrics)} {win}")}
<h3>Within each target</h3>
{_stats_html(tables["stats_by_target.csv"], "stats_by_target.csv", metrics, lead=["target_label"],
             caption=f"ON vs OFF within each target; {windowed_words(metrics)} {win}")}
{report_design.sites_html(within, tables, study)}
{report_sections.sensitivity_html(within, options, metrics, confidence)}
{_bar_figures(pngs, metrics)}
{report_tct.tct_html(within, tables, options, pngs["tct_survival"], confidence) if timed else ""}
<figure><h2>Per participant</h2>{_img(pngs["paired"], "paired per-participant changes")}
<p class="caption">Grey lines: participants (spread a little sideways so equal values stay apart); black: the median
across participants.</p></figure>
{_html_table(per, "participants.csv", per_cols, caption=f"Per participant and mode; {windowed_words(metrics)} {win}")}
{report_sections.trade_html(within, tables, options, pngs["speed_accuracy"], confidence) if timed else ""}
{sections_html}
<h2>Force through the pipeline</h2>
<p class="caption">Top: the task force the trial was judged on, the force rendered on the haptic device, the target
band and the error window; bottom, on an axis of its own: the raw sensor force, the tool's weight included.</p>
{"".join(f"<figure>{_img(p, t)}</figure>" for t, p in examples)}
{report_sections.secondary_html(within, tables, pngs["learning"], list(target_order), confidence)}
{power_html}
{_record_html(study, tables, within)}
<h2>Methods</h2>
{_methods(study, table, options, zero_method, confidence, excluded, n_participants, within)}
{_sessions_html(tables["sessions.csv"], within)}
</body></html>
"""
