"""The report's between-group part, where the protocol declares ``[groups]`` (:mod:`protocol.study.groups`).

From :func:`analysis.stats.groups.analyse_groups`:

* ``groups.csv``: each group's ON-vs-OFF tests, the report's own (stats.csv's columns), with the group and its n;
* ``group_interaction.csv``: the group × haptics interaction models' fixed effects, with the method and formula;
* ``group_tests.csv``: each group's per-participant ON − OFF effects against the reference group's (Mann–Whitney U);
* the page's section (:func:`groups_html`).

A study without ``[groups]`` -- the paper's -- gets no file or section from here.
"""

from __future__ import annotations

import html

import pandas as pd

from analysis.reading import codebook
from analysis.reading.annotations import Annotations
from analysis.reading.codebook import export, exported_name
from analysis.reading.metrics import MetricOptions
from analysis.report.html_parts import fmt, fmt_p, html_table
from analysis.stats.aggregate import METRIC_LABELS
from analysis.stats.groups import FORMULA, FORMULA_GEE, GroupAnalysis, analyse_groups
from protocol.study.labels import plural

__all__ = ["group_analysis", "group_tables", "groups_html"]


def group_analysis(ann: Annotations, trials: pd.DataFrame, overall: pd.DataFrame, target_order: list[str],
                   options: MetricOptions, zero_method: str, confidence: float) -> GroupAnalysis | None:
    """The between-group analyses of the participants analysed (None: the protocol declares no ``[groups]``)."""
    if ann.groups is None or not len(overall):
        return None
    return analyse_groups(trials, overall, ann.covariates, ann.groups.by, ann.groups.levels, target_order, options,
                          zero_method=zero_method, confidence=confidence)


def group_tables(g: GroupAnalysis | None, *, rounded: bool = True) -> dict[str, pd.DataFrame]:
    """The three files (none without groups)."""
    if g is None:
        return {}
    effects = g.effects
    if len(effects) and "n_used" in effects.columns:
        stats = export(effects.drop(columns=["group", "n_participants"]), "stats.csv", rounded=rounded)
        effects = pd.concat([effects[["group", "n_participants"]], stats], axis=1)
    else:
        effects = export(effects, "groups.csv", rounded=rounded)
    tables = {"groups.csv": effects,
              "group_interaction.csv": export(g.interaction, "group_interaction.csv", rounded=rounded),
              "group_tests.csv": export(g.between, "group_tests.csv", rounded=rounded)}
    return {name: _whole(frame, name) for name, frame in tables.items()}


def _whole(frame: pd.DataFrame, file: str) -> pd.DataFrame:
    """``frame`` with its counts whole numbers (a group not tested has none: empty, not NaN that makes them
    floats)."""
    out = frame.copy()
    for name in out.columns:
        c = codebook.lookup(file, name)
        if c is not None and c.type == "integer" and pd.api.types.is_float_dtype(out[name]):
            out[name] = out[name].round().astype("Int64")
    return out


def _effect_lines(g: GroupAnalysis) -> list[str]:
    lines = []
    for r in g.counts.itertuples():
        if not r.group:
            lines.append(f"<li>{html.escape(r.note)}</li>")
            continue
        if not r.tested:
            lines.append(f"<li><b>{html.escape(r.group)}</b>, n = {r.n_participants}: {html.escape(r.note)}</li>")
            continue
        mine = g.effects[g.effects["group"] == r.group]
        parts = [f"{html.escape(METRIC_LABELS.get(str(m.metric), str(m.metric)))}: median OFF {fmt(m.median_off)}, "
                 f"ON {fmt(m.median_on)}, shift ON − OFF {fmt(m.hl_estimate)}, p = {fmt_p(m.p_value)}"
                 + (f" (Holm {fmt_p(m.p_holm)})" if pd.notna(m.p_holm) else "") + f", {fmt(int(m.n_used))} pairs"
                 for m in mine.itertuples()]
        lines.append(f"<li><b>{html.escape(r.group)}</b>, n = {r.n_participants} participants: "
                     + "; ".join(parts) + "</li>")
    return lines


def _interaction_lines(g: GroupAnalysis) -> list[str]:
    rows = g.interaction[g.interaction["term"].fillna("").str.startswith("haptics_on_x_group_")]
    lines = []
    for r in rows.itertuples():
        lines.append(f"<li>{html.escape(str(r.outcome))}: {html.escape(str(r.term))} = {fmt(r.estimate)} "
                     f"{html.escape(str(r.scale))} [{fmt(r.ci_low)}, {fmt(r.ci_high)}], p = {fmt_p(r.p_value)}, "
                     f"{r.n_participants} participants, {r.n_obs} trials"
                     + (f" ({html.escape(str(r.note))})" if r.note else "") + "</li>")
    for r in g.interaction[g.interaction["term"].fillna("") == ""].itertuples():
        lines.append(f"<li>{html.escape(str(r.outcome or ''))}: {html.escape(str(r.note))}</li>")
    return lines


def _between_lines(g: GroupAnalysis) -> list[str]:
    lines = []
    for r in g.between.itertuples():
        if not r.computable:
            lines.append(f"<li>{html.escape(exported_name(str(r.metric)) if pd.notna(r.metric) else '')} "
                         f"{html.escape(str(r.note))}</li>")
            continue
        lines.append(f"<li>{html.escape(METRIC_LABELS.get(str(r.metric), str(r.metric)))}: median ON − OFF "
                     f"{html.escape(str(r.group))} {fmt(r.median_effect_group)} (n = {r.n_group}) against "
                     f"{html.escape(str(r.reference))} {fmt(r.median_effect_reference)} (n = {r.n_reference}); "
                     f"U = {fmt(r.u_statistic, 1)}, p = {fmt_p(r.p_value)} ({html.escape(str(r.method))}), "
                     f"rank-biserial r = {fmt(r.rank_biserial, 2)}</li>")
    return lines


def groups_html(g: GroupAnalysis | None) -> str:
    """The page's section ("" without groups)."""
    if g is None:
        return ""
    counts = ", ".join(f"{r.group} {r.n_participants}" for r in g.counts.itertuples() if r.group)
    return (
        f"<h2>Between groups: {html.escape(g.by)}</h2>"
        f"<p>The participants analysed by their {html.escape(g.by)} ({counts}; a group of fewer than 2 is not "
        f"tested). <b>Each group's haptic effect</b> (groups.csv): the report's tests within the group -- the paired "
        f"Wilcoxon signed-rank test of the participants' OFF and ON means, the Hodges–Lehmann shift, Holm across the "
        f"primary measures:</p><ul>{''.join(_effect_lines(g))}</ul>"
        f"<p><b>The group × haptics interaction</b> (group_interaction.csv): trial-level models, a linear mixed "
        f"model (statsmodels MixedLM, REML, random intercept and random slope of haptic mode per participant) "
        f"<code>{html.escape(FORMULA)}</code> for the continuous measures, and the report's logistic GEE "
        f"(exchangeable within a participant, Mancl–DeRouen standard errors) <code>{html.escape(FORMULA_GEE)}"
        f"</code> for success; the reference group is {html.escape(g.tested[0]) if g.tested else '–'}, and "
        f"haptics_on_x_group_&lt;level&gt; is how much larger that group's ON − OFF effect is:</p>"
        f"<ul>{''.join(_interaction_lines(g))}</ul>"
        f"<p><b>The per-participant effects between groups</b> (group_tests.csv): each participant's ON − OFF "
        f"difference of their means, compared with the reference group's by the two-sided Mann–Whitney U test "
        f"(exact without ties; each comparison its own p):</p><ul>{''.join(_between_lines(g))}</ul>"
        + html_table(g.counts, "groups.csv", ["group", "n_participants"],
                     caption=f"{plural(int(g.counts['n_participants'].sum()), 'participant')} by group")
    )
