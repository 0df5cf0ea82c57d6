"""The report's "what n would a study need?" section: the power of each test against the number of participants,
from :func:`analysis.planning.power.report_section` (``report --power``)."""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import Any

import numpy as np

from analysis.report.html_parts import img as _img
from analysis.report.html_parts import plural
from protocol.metrics import Metric, family_word

__all__ = ["power_html"]

#: Headings of the power table's columns (``target`` and ``measure`` are the row labels, as in the test tables).
_POWER_HEADINGS = {"scope": "target", "metric": "measure", "direction": "pilot shows", "n80": "n for 80 %",
                   "n80_holm": "n for 80 % (Holm)", "n90": "n for 90 %", "n90_holm": "n for 90 % (Holm)"}


def power_html(section: Any, metrics: Sequence[Metric]) -> str:
    """The "what n would a study need?" section: a notice when it could not be estimated, else a real table.

    ``section`` is an :class:`analysis.planning.power.ReportPower`, of a study with these ``metrics`` (its tasks':
    Holm's family is theirs).  The table is built
    from the structured result (:func:`analysis.planning.power_plan.plan_table`); columns
    with no value in any row are left out.  In print, its rows never split,
    its head repeats on every page and the heading stays with it (``_CSS``).
    """
    from analysis.planning.power import DIRECTION_TEXT, is_family_row, metric_label
    from analysis.planning.power_plan import plan_table

    head = "<h2>What n would a study need?</h2>"
    if section.result is None:
        return (f'<section class="power"><div class="power-head">{head}<p class="warn">'
                f'{html.escape(section.notice)}</p></div></section>')
    r = section.result
    table = plan_table(r)
    cells: dict[str, list[str]] = {}
    for col in table.columns:
        if col == "scope":
            cells[col] = [html.escape(str(v)) for v in table[col]]
        elif col == "metric":
            cells[col] = [html.escape(metric_label(str(v))) for v in table[col]]
        elif col == "direction":
            cells[col] = [DIRECTION_TEXT.get(str(v), str(v)) for v in table[col]]
        elif col.startswith("power_n"):
            cells[col] = ["" if not np.isfinite(v) else f"{v:.0%}" for v in table[col]]
        else:
            cells[col] = [html.escape(str(v)) for v in table[col]]
    shown = [c for c in table.columns if any(cells[c])]  # a column empty in every row is left out
    heads = "".join(f"<th>{html.escape(_POWER_HEADINGS.get(c, 'n = ' + c.removeprefix('power_n')))}</th>"
                    for c in shown)
    body = []
    for i, metric in enumerate(table["metric"]):
        cls = ' class="family"' if is_family_row(metric) else ""
        tds = "".join(f'<td class="m">{cells[c][i]}</td>' if c in ("scope", "metric") else f"<td>{cells[c][i]}</td>"
                      for c in shown)
        body.append(f"<tr{cls}>{tds}</tr>")
    tct = "over successful trials" if r.options.tct_policy == "successful" else "failures counted at the trial cap"
    lead = (f"<p>Resampling this study's {plural(r.n_pool, 'participant')} with both haptic modes with replacement "
            f"({r.resamples} studies per n, seed {r.seed}): the power of each ON-vs-OFF Wilcoxon test (p &lt; "
            f"{r.alpha:g}; TCT {tct}) to detect the effect <b>in the direction this study shows</b>"
            f"{' (pilot shows)' if 'direction' in shown else ''}. "
            "n for 80 %: the smallest n tried from which on power stays at or above 80 %; '&gt; N (x %)': not "
            f"reached by the largest n tried. Holm: with Holm's correction across the {family_word(metrics)} primary "
            "measures, as the significance marks above (a secondary measure has none). power.csv has every number, "
            "with the two-sided rejection rate "
            "(power_two_sided) and the Monte Carlo intervals.</p>")
    caption = (f"<caption>Participants needed, and power at each n ({r.interval_level:.0%} Monte Carlo intervals "
               "in power.csv)</caption>")
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in r.notes)
    return (f'<section class="power"><div class="power-head">{head}{lead}</div>'
            f'<div class="scroll"><table class="stats power">{caption}<thead><tr>{heads}</tr></thead>'
            f'<tbody>{"".join(body)}</tbody></table></div>'
            + (f'<ul class="notes">{notes}</ul>' if notes else "")
            + (f"<figure>{_img(section.png, 'power of each test against the number of participants')}</figure>"
               if section.png else "") + "</section>")
