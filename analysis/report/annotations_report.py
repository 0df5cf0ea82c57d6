"""The report's part about who the participants are, what they answered and what the experimenter noted.

From :func:`analysis.reading.annotations.read_annotations` and the scores of :mod:`analysis.stats.questionnaires`:

* ``participants.csv`` (and its wide and by-target twins) gains a column per declared covariate, after
  ``participant_number`` (:func:`with_covariates`);
* ``questionnaires.csv`` (every sheet's scores), ``questionnaire_summary.csv`` (per block) and
  ``questionnaire_tests.csv`` (ON against OFF, paired Wilcoxon, with n), and ``notes.csv`` (every note), each only
  when the study has some (:func:`annotation_tables`);
* the notes the experimenter marked a deviation join ``deviations.csv`` (:func:`noted_deviations`);
* the codebook's words for each covariate's column come from its declaration (:func:`covariate_codebook`);
* the page's section (:func:`annotations_html`).

A study without covariates, questionnaires or notes -- the paper's -- gets no column, file or section from here.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import pandas as pd

from analysis.reading.annotations import Annotations
from analysis.reading.codebook import export, p_text
from analysis.report.html_parts import fmt, html_table
from analysis.stats import questionnaires as qs
from protocol.study.covariates import Covariate
from protocol.study.labels import plural
from protocol.study.questionnaires import SESSION

__all__ = ["QuestionnaireResults", "annotate", "annotation_tables", "annotations_html", "covariate_codebook",
           "noted_deviations", "questionnaire_results", "with_covariates"]

#: The participants' tables a covariate column is added to.
PARTICIPANT_FILES = ("participants.csv", "participants_wide.csv", "participants_by_target.csv")


@dataclass(frozen=True, slots=True)
class QuestionnaireResults:
    """The sheets scored (:func:`analysis.stats.questionnaires.scores`), their summary and the mode tests."""

    scored: pd.DataFrame
    summary: pd.DataFrame
    tests: pd.DataFrame


def questionnaire_results(ann: Annotations, analysed: pd.DataFrame) -> QuestionnaireResults:
    """Score the answers of the participants analysed (``analysed``: the trials the report analyses)."""
    codes = set(analysed["participant_code"]) if len(analysed) else set()
    sessions = set(analysed["session_id"]) if len(analysed) else set()
    answers = ann.answers[ann.answers["participant_code"].isin(codes) & ann.answers["session_id"].isin(sessions)]
    scored = qs.scores(answers, ann.questionnaires)
    return QuestionnaireResults(scored, qs.summary(scored), qs.mode_tests(scored))


def with_covariates(tables: dict[str, pd.DataFrame], ann: Annotations) -> dict[str, pd.DataFrame]:
    """The participants' tables with a column per declared covariate after ``participant_number`` (none: as
    they were)."""
    names = [c.name for c in ann.declared]
    if not names:
        return tables
    out = dict(tables)
    for file in PARTICIPANT_FILES:
        frame = tables.get(file)
        if frame is None or "participant_code" not in frame.columns:
            continue
        merged = frame.merge(ann.covariates[["participant_code", *names]], on="participant_code", how="left")
        at = list(frame.columns).index("participant_number") + 1 if "participant_number" in frame.columns else 1
        order = [*frame.columns[:at], *names, *frame.columns[at:]]
        out[file] = merged[order]
    return out


def noted_deviations(ann: Annotations, deviations: pd.DataFrame) -> pd.DataFrame:
    """``deviations.csv``'s rows with the notes the experimenter marked a deviation (kind ``note``) after them."""
    marked = ann.notes[ann.notes["deviation"].astype(bool)] if len(ann.notes) else ann.notes
    if marked.empty:
        return deviations
    rows = pd.DataFrame({
        "database": marked["database"], "participant_code": marked["participant_code"],
        "session_id": marked["session_id"], "kind": "note", "t_s": marked["t_s"].astype(float),
        "detail": [f"{'session' if pd.isna(n) else f'trial {int(n)}'}: {t}"
                   + (" (noted after the session)" if after else "")
                   for n, t, after in zip(marked["trial_number"], marked["text"], marked["written_after"],
                                          strict=True)],
    })
    return pd.concat([deviations, rows], ignore_index=True) if len(deviations) else rows.reset_index(drop=True)


def annotation_tables(ann: Annotations, results: QuestionnaireResults, *, rounded: bool = True
                      ) -> dict[str, pd.DataFrame]:
    """The files of the questionnaires and notes, each only when the study has some."""
    out: dict[str, pd.DataFrame] = {}
    if len(results.scored):
        out["questionnaires.csv"] = export(results.scored, "questionnaires.csv", rounded=rounded)
        out["questionnaire_summary.csv"] = export(results.summary, "questionnaire_summary.csv", rounded=rounded)
    if len(results.tests):
        out["questionnaire_tests.csv"] = export(results.tests, "questionnaire_tests.csv", rounded=rounded)
    if len(ann.notes):
        out["notes.csv"] = export(ann.notes, "notes.csv", rounded=rounded)
    return out


def annotate(tables: dict[str, pd.DataFrame], ann: Annotations, results: QuestionnaireResults, *,
             rounded: bool = True) -> dict[str, pd.DataFrame]:
    """The report's tables with the covariates' columns and the files of the questionnaires and notes."""
    return {**with_covariates(tables, ann), **annotation_tables(ann, results, rounded=rounded)}


def covariate_codebook(declared: Sequence[Covariate]) -> dict[tuple[str, str], tuple[str, str, str]]:
    """(file, column) → (type, unit, description) of each covariate's column in the participants' tables."""
    return {(file, c.name): ("text" if c.kind == "category" else "number", c.unit,
                             f"the participant's covariate, as the protocol declares it: {c.described()}; given "
                             "when they were registered (empty: not given)")
            for c in declared for file in PARTICIPANT_FILES}


def _covariate_lines(ann: Annotations, analysed: set[str]) -> list[str]:
    """Each covariate in words over the participants analysed: the levels' counts, or the numbers' range."""
    cov = ann.covariates[ann.covariates["participant_code"].isin(analysed)]
    lines = []
    for c in ann.declared:
        values = cov[c.name].dropna() if c.name in cov.columns else pd.Series(dtype=object)
        if c.kind == "category":
            counts = values.value_counts()
            given = ", ".join(f"{level} {int(counts.get(level, 0))}" for level in c.levels)
        else:
            x = pd.to_numeric(values, errors="coerce").dropna()
            given = (f"median {fmt(x.median())}{' ' + c.unit if c.unit else ''} (range {fmt(x.min())}–"
                     f"{fmt(x.max())}), n = {len(x)}" if len(x) else "none given")
        lines.append(f"<li>{html.escape(c.question)} ({html.escape(c.name)}): {html.escape(given)}</li>")
    return lines


def annotations_html(ann: Annotations, results: QuestionnaireResults, analysed: Mapping[str, object]) -> str:
    """The page's section: the participants described, the questionnaires (ON against OFF with n), the notes.
    "" for a study without any of them."""
    parts: list[str] = []
    codes = set(analysed)
    if ann.declared:
        parts.append("<h3>The participants described</h3><p>What the protocol asked when each participant was "
                     "registered (participants.csv has each participant's values):</p><ul>"
                     + "".join(_covariate_lines(ann, codes)) + "</ul>")
    if len(results.tests):
        t = results.tests
        lines = []
        for r in t.itertuples():
            shift = r.hl_estimate if isinstance(r.hl_estimate, float) and math.isfinite(r.hl_estimate) else None
            lines.append(f"<li>{html.escape(str(r.questionnaire))} {html.escape(str(r.measure))}: median OFF "
                         f"{fmt(r.median_off)}, ON {fmt(r.median_on)}, Hodges–Lehmann shift ON − OFF "
                         f"{fmt(shift)} [{fmt(r.hl_ci_low)}, {fmt(r.hl_ci_high)}], Wilcoxon signed-rank "
                         f"p = {p_text(r.p_value)} ({html.escape(str(r.method))}), n = {r.n_pairs}</li>")
        parts.append("<h3>Questionnaires</h3><p>Each answered sheet scored (NASA-TLX: raw, the mean of the six "
                     "ratings, and weighted, Σ weight × rating / 15, Hart &amp; Staveland 1988; Hart 2006; "
                     "questionnaires.csv), each measure compared within participants between the blocks of the two "
                     "haptic modes by the paired Wilcoxon signed-rank test on the participants who answered after "
                     "both (questionnaire_tests.csv); secondary outcomes, each with its own p, not corrected across "
                     "them:</p><ul>" + "".join(lines) + "</ul>")
    after = results.summary[results.summary["block"] == SESSION] if len(results.summary) else results.summary
    if len(after):
        parts.append(("" if len(results.tests) else "<h3>Questionnaires</h3>")
                     + "<p>Answered after the session (no comparison of modes; questionnaire_summary.csv):</p>"
                     + html_table(after, "questionnaire_summary.csv"))
    if len(ann.notes):
        mine = ann.notes[ann.notes["participant_code"].isin(codes)]
        parts.append(f"<h3>The experimenter's notes</h3><p>{plural(len(mine), 'note')} on the sessions analysed "
                     "(notes.csv; those marked a deviation are listed under Deviations from the protocol too):</p>"
                     + html_table(mine[["participant_code", "session_id", "trial_number", "t_s", "deviation", "text"]],
                                  "notes.csv"))
    return "".join(parts)
