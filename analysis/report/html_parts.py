"""The small pieces every section of report.html is made of: numbers, tables with the codebook's headings, figures.

Shared by :mod:`analysis.report.report_html` (the page) and :mod:`analysis.report.report_sections` (its
within-participant sections).  A figure is shown at the size it was drawn for (its PNG's pixels at 300 dpi),
never stretched to the page: a one-column figure stays one column wide, on screen and on paper.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from analysis.reading import codebook
from analysis.reading.codebook import p_text
from protocol.study.labels import plural

if TYPE_CHECKING:
    from analysis.reading.load import StudyData

__all__ = ["fmt", "fmt_p", "fmt_w", "html_table", "img", "p_text", "part_banner", "part_title", "plural", "th"]

#: The resolution the figures are saved at (:func:`analysis.plots.figures.save`).
_DPI = 300


def fmt(v: object, digits: int = 3) -> str:
    """A value for a table cell: integers as they are, floats to ``digits`` decimals (tiny or huge in g)."""
    if v is None or v is pd.NA:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if math.isnan(f):
            return "–"
        if f != 0 and (abs(f) < 1e-3 or abs(f) >= 1e5):
            return f"{f:.{digits}g}"
        return f"{f:.{digits}f}"
    return html.escape(str(v))


def fmt_w(v: object) -> str:
    """A signed-rank statistic with the precision it has: a sum of ranks is a whole or half number (``0``, ``7.5``)."""
    if not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(float(v)):
        return "–"
    f = float(v)
    return str(int(f)) if f.is_integer() else (f"{f:.1f}" if (2 * f).is_integer() else f"{f:.2f}")


def fmt_p(v: object) -> str:
    """:func:`p_text` for the page (HTML)."""
    return html.escape(p_text(v))


def th(file: str, column: str) -> str:
    """A table heading: the codebook's short label, its description on hover."""
    entry = codebook.lookup(file, column)
    tip = f' title="{html.escape(entry.described(codebook.metric_words(None)))}"' if entry is not None else ""
    return f"<th{tip}>{html.escape(codebook.label(file, column))}</th>"


def html_table(frame: pd.DataFrame, file: str, columns: Sequence[str] | None = None,
               cell: Mapping[str, Callable[[Any], str]] | None = None, caption: str = "") -> str:
    """A table of an exported CSV's rows, with readable headings; ``cell`` formats some columns specially."""
    cols = list(columns) if columns else list(frame.columns)
    special = cell or {}
    head = "".join(th(file, c) for c in cols)
    body = []
    for _, row in frame.iterrows():
        cells = "".join(f"<td>{special[c](row[c]) if c in special else fmt(row[c])}</td>" for c in cols)
        body.append(f"<tr>{cells}</tr>")
    cap = f"<caption>{caption}</caption>" if caption else ""
    return (f'<div class="scroll"><table>{cap}<thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody>'
            "</table></div>")


def img(png: bytes, alt: str) -> str:
    """A figure, embedded, at the width it was drawn for (at most the page's)."""
    width = int.from_bytes(png[16:20], "big") / _DPI if png[:8] == b"\x89PNG\r\n\x1a\n" else 0.0
    size = f' style="width:{width:.2f}in"' if width > 0 else ""
    return (f'<img alt="{html.escape(alt)}"{size} '
            f'src="data:image/png;base64,{base64.b64encode(png).decode("ascii")}">')


def part_banner(study: StudyData) -> str:
    """Above a part's report (a study of several parts, :mod:`analysis.report.plan_report`): which part, of what
    task, and the way back to the plan's page -- read alone (printed, sent on), a part's report looked like a whole
    study's.  "" for a study's report."""
    part = study.part
    if part is None:
        return ""
    kind = next(iter(study.tasks.values())).kind if study.tasks else ""  # a part is one task
    return (f'<p style="border-bottom:1px solid #999;padding-bottom:4px">Part <b>{html.escape(part)}</b> '
            f"({html.escape(kind.replace('_', ' '))}) of a study of several parts: this part's sessions only. "
            '<a href="../report.html">The plan and the other parts</a></p>')


def part_title(part: str | None, title: str) -> str:
    """A page's title, led by its part's name in a part's report."""
    return html.escape(title if part is None else f"{part} — {title}")

