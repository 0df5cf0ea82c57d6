"""The questionnaires scored and compared: NASA-TLX per haptic mode and its paired Wilcoxon test, Likert items.

Each answered sheet is scored by the questionnaire's one definition (:mod:`protocol.study.tlx`: raw TLX, the mean
of the six ratings; weighted TLX, Σ weight × rating / 15; and each subscale's rating), a Likert item is its rating.
:func:`scores` gives one row per participant, sheet and measure (questionnaires.csv); :func:`summary` each
measure's n, mean, SD and median per block; :func:`mode_tests` compares the blocks of the two haptic modes within
participants -- the paired Wilcoxon signed-rank test of :func:`analysis.stats.wilcoxon.paired_wilcoxon`, with the
Hodges–Lehmann shift, on the participants who answered after both blocks (their n is said).  The measures are
secondary outcomes, each with its own p (no correction across them, said on the page).
"""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from analysis.stats.wilcoxon import paired_wilcoxon
from protocol.study import tlx
from protocol.study.questionnaires import SESSION, Questionnaire

__all__ = ["SCORE_COLUMNS", "TEST_COLUMNS", "mode_tests", "scores", "summary"]

#: The columns of questionnaires.csv.
SCORE_COLUMNS = ("participant_code", "participant_number", "session_id", "questionnaire", "kind", "block", "measure",
                 "value")
#: The columns of questionnaire_tests.csv.
TEST_COLUMNS = ("questionnaire", "measure", "n_pairs", "median_off", "median_on", "hl_estimate", "hl_ci_low",
                "hl_ci_high", "statistic", "p_value", "method", "note")


def _sheet_scores(q: Questionnaire, sheet: pd.DataFrame) -> list[tuple[str, float]]:
    """(measure, value) of one answered sheet."""
    if q.kind != "nasa_tlx":
        return [(str(r.item), float(r.rating)) for r in sheet.itertuples() if r.rating == r.rating]
    ratings = {str(r.item): float(r.rating) for r in sheet.itertuples() if r.rating == r.rating}
    choices = {str(r.item): str(r.choice) for r in sheet.itertuples() if isinstance(r.choice, str)}
    s = tlx.score(ratings, choices if q.weighted and choices else None)
    out = [("tlx_raw", s.raw)]
    if s.weighted is not None:
        out.append(("tlx_weighted", s.weighted))
    return out + [(f"tlx_{sub.id}", ratings[sub.id]) for sub in tlx.SUBSCALES]


def scores(answers: pd.DataFrame, questionnaires: Sequence[Questionnaire]) -> pd.DataFrame:
    """One row per participant, session, questionnaire, block and measure (:data:`SCORE_COLUMNS`)."""
    by_name = {q.name: q for q in questionnaires}
    rows: list[tuple[object, ...]] = []
    if len(answers):
        keys = ["participant_code", "participant_number", "session_id", "questionnaire", "block"]
        for (code, number, sid, name, block), sheet in answers.groupby(keys, sort=False):
            q = by_name.get(str(name))
            if q is None:
                continue
            for measure, value in _sheet_scores(q, sheet):
                rows.append((code, number, sid, name, q.kind, block, measure, value))
    return pd.DataFrame(rows, columns=list(SCORE_COLUMNS))


def summary(scored: pd.DataFrame) -> pd.DataFrame:
    """Each measure's n, mean, SD and median per questionnaire and block (participants as units)."""
    cols = ["questionnaire", "block", "measure", "n", "mean", "sd", "median"]
    if scored.empty:
        return pd.DataFrame(columns=cols)
    per = scored.groupby(["questionnaire", "block", "measure", "participant_code"], sort=False)["value"].mean()
    g = per.groupby(level=["questionnaire", "block", "measure"], sort=False)
    out = pd.DataFrame({"n": g.count(), "mean": g.mean(), "sd": g.std(ddof=1), "median": g.median()}).reset_index()
    return out[cols]


def mode_tests(scored: pd.DataFrame) -> pd.DataFrame:
    """ON against OFF for every measure asked after both modes' blocks: the paired Wilcoxon signed-rank test on
    the participants who answered after both (:data:`TEST_COLUMNS`; d = ON − OFF, so a negative shift is less
    workload with haptic feedback)."""
    rows: list[tuple[object, ...]] = []
    blocked = scored[scored["block"] != SESSION] if len(scored) else scored
    if len(blocked):
        per = blocked.groupby(["questionnaire", "measure", "participant_code", "block"], sort=False)["value"].mean()
        for (name, measure), part in per.groupby(level=["questionnaire", "measure"], sort=False):
            wide = part.unstack("block")
            if not {"on", "off"} <= set(wide.columns):
                continue
            both = wide[["off", "on"]].dropna()
            res = paired_wilcoxon(both["off"].to_numpy(float), both["on"].to_numpy(float), metric=str(measure))
            rows.append((name, measure, res.n_pairs, res.median_off, res.median_on, res.hl_estimate, res.hl_ci_low,
                         res.hl_ci_high, res.statistic, res.p_value, res.method, res.note))
    return pd.DataFrame(rows, columns=list(TEST_COLUMNS))
