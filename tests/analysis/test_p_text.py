"""One rendering of a p-value: the page, the CSVs, the terminal and the figures' captions."""

from __future__ import annotations

import math
from types import SimpleNamespace

from analysis.report.html_parts import fmt_p, p_text
from analysis.stats.trade import rm_caption


def test_a_p_value_reads_the_same_under_a_figure_as_in_the_tables() -> None:
    assert p_text(1 / 32) == "0.03125" and fmt_p(1 / 32) == "0.03125"
    assert p_text(3e-5) == "< 0.0001" and fmt_p(3e-5) == "&lt; 0.0001"
    assert p_text(math.nan) == "–" and p_text(None) == "–"
    row = SimpleNamespace(computable=True, r_rm=-0.3123, ci_low=-0.55, ci_high=-0.031, df=40, p_value=1 / 32)
    assert rm_caption(row) == "r_rm = -0.31 [-0.55, -0.03], df = 40, p = 0.03125"  # it said p = 0.031
    assert rm_caption(SimpleNamespace(**{**vars(row), "p_value": 2e-6})).endswith("df = 40, p < 0.0001")
