"""The codebook's entries for the files of the questionnaires and the experimenter's notes (written only when a
study has some: :mod:`analysis.report.annotations_report`).  A covariate's column in the participants' tables is
described from its declaration there."""

from __future__ import annotations

from analysis.reading.codebook_columns import Column

__all__ = ["ANNOTATION_COLUMNS"]

_Q = ("questionnaires.csv",)
_QS = ("questionnaire_summary.csv",)
_QT = ("questionnaire_tests.csv",)
_QA = (*_Q, *_QS, *_QT)
_N = ("notes.csv",)
_MEASURE = ("the measure: tlx_raw (NASA-TLX raw, the mean of the six ratings), tlx_weighted (Σ weight × rating / 15, "
            "the weights from the 15 pairs; Hart & Staveland 1988), tlx_<subscale> (one subscale's rating, 0–100), or "
            "a Likert item's id (its rating on its scale)")

ANNOTATION_COLUMNS: tuple[Column, ...] = (
    Column("questionnaire", "the questionnaire's name, as the protocol declares it", type="text", files=_QA),
    Column("kind", "nasa_tlx or likert", type="text", files=_Q),
    Column("block", "what the sheet was answered after: the block of one haptic mode (on, off) or the whole "
           "session (session)", type="text", files=(*_Q, *_QS)),
    Column("measure", _MEASURE, type="text", files=_QA),
    Column("value", "the measure's value for this sheet (NASA-TLX 0–100, higher is more workload; a Likert item on "
           "its scale)", decimals=4, files=_Q),
    Column("n", "participants with a value", "count", "integer", files=_QS),
    Column("mean", "mean over the participants", decimals=4, files=_QS),
    Column("sd", "standard deviation over the participants (n − 1)", decimals=4, files=_QS),
    Column("median", "median over the participants", decimals=4, files=_QS),
    Column("n_pairs", "participants who answered after a block of each mode (the test's pairs)", "count", "integer",
           files=_QT),
    Column("median_off", "median over those participants, haptics OFF block", decimals=4, files=_QT),
    Column("median_on", "median over those participants, haptics ON block", decimals=4, files=_QT),
    Column("hl_estimate", "Hodges–Lehmann shift ON − OFF (negative: less with haptic feedback)", decimals=4,
           files=_QT),
    Column("hl_ci_low", "lower end of the shift's distribution-free interval", decimals=4, files=_QT),
    Column("hl_ci_high", "upper end of the shift's distribution-free interval", decimals=4, files=_QT),
    Column("statistic", "Wilcoxon signed-rank statistic, min(W+, W−), as SciPy reports it", decimals=4, files=_QT),
    Column("p_value", "two-sided p of the paired Wilcoxon signed-rank test (a secondary outcome: its own p, not "
           "corrected across the questionnaire's measures)", significant=4, files=_QT),
    Column("method", "exact, permutation or approx: how the p was computed (SciPy's rule)", type="text", files=_QT),
    Column("note", "why a test is not computable, or what was degenerate; empty otherwise", type="text", files=_QT),
    Column("trial_number", "the trial the note is about, numbered from 1 (empty: the session)", "", "integer",
           files=_N),
    Column("t_s", "session clock when the note was written (empty: added after the session)", "s", files=_N,
           decimals=3),
    Column("written_after", "true: added after the session (haptic-study note)", type="boolean", files=_N),
    Column("deviation", "true: the experimenter marked it a deviation from the protocol (listed in deviations.csv)",
           type="boolean", files=_N),
    Column("text", "the note, as the experimenter wrote it", type="text", files=_N),
    Column("written_at", "when the note was written, ISO 8601 UTC", type="text", files=_N),
)
