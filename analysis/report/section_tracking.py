"""Force tracking's section of the report: how the force follows a moving target, and error against speed.

The section of the tracking task's kind (:mod:`analysis.report.task_sections`), shown when its target moves.  It gathers
what a tracking study asks beyond the error measures:

* the measures of how the force follows the target (the study's metrics drawn in the ``tracking`` figure: lag and
  gain), each one value per participant per mode (the mean of their trials), tested ON vs OFF with its own p
  (:mod:`analysis.stats.aggregate`, rows of ``stats.csv``), the method named;
* the speed–accuracy trade across the protocol's profiles: each participant's tracking error (mean RMSE) per target
  against the target's speed, the slope per participant and mode, and its test ON vs OFF
  (:mod:`analysis.stats.target_speed`): ``target_speed.csv``, ``target_speed_slopes.csv``,
  ``target_speed_test.csv`` and the figure ``target_speed``.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from analysis.plots.figures import MODE_COLORS, MODE_MARKERS, PAGE_IN, margins, save, styled
from analysis.reading import codebook
from analysis.report.html_parts import fmt, fmt_p, img, plural
from analysis.report.measures import listed
from analysis.report.task_sections import SectionInput, SectionOutput
from analysis.stats.target_speed import TargetSpeedTrade, target_speed_trade
from protocol.metrics import Metric, family_word, primary

__all__ = ["FILES", "SECTION", "TITLE", "follow_measures", "speed_figure", "tracking_body", "tracking_tables"]

#: The section's heading.
TITLE = "Tracking a moving target"

#: The section's CSV files.
FILES = ("target_speed.csv", "target_speed_slopes.csv", "target_speed_test.csv")
_NAMES = {"off": "haptics OFF", "on": "haptics ON"}


def follow_measures(metrics: Sequence[Metric]) -> tuple[Metric, ...]:
    """The study's measures of how the force follows a moving target (those drawn in its ``tracking`` figure)."""
    return tuple(m for m in metrics if m.figure == "tracking")


def tracking_tables(trade: TargetSpeedTrade, *, rounded: bool = True) -> dict[str, pd.DataFrame]:
    """The section's CSV tables, as written (exported names, rounded as the codebook says)."""
    return {
        "target_speed.csv": codebook.export(trade.by_target, "target_speed.csv", rounded=rounded),
        "target_speed_slopes.csv": codebook.export(trade.slopes, "target_speed_slopes.csv", rounded=rounded),
        "target_speed_test.csv": codebook.export(trade.test, "target_speed_test.csv", rounded=rounded),
    }


@styled
def _figure(trade: TargetSpeedTrade) -> Figure:
    fig = Figure(figsize=(PAGE_IN * 0.62, 3.0))
    margins(fig, 0.6, 0.2, 0.5, 0.3)
    ax = fig.add_subplot()
    for mode in ("off", "on"):
        mine = trade.by_target[trade.by_target["haptic_mode"] == mode]
        for _, g in mine.groupby("participant_code"):
            g = g.sort_values("target_speed_n_per_s")
            ax.plot(g["target_speed_n_per_s"], g["rmse_n"], color=MODE_COLORS[mode], alpha=0.3, linewidth=0.7)
        mean = mine.groupby("target_speed_n_per_s")["rmse_n"].mean()
        ax.plot(mean.index, mean.to_numpy(), color=MODE_COLORS[mode], marker=MODE_MARKERS[mode], linewidth=1.6,
                label=f"{_NAMES[mode]}: mean across participants")
    ax.set_xlabel("target speed, mean |dF*/dt| where it moves (N/s)")
    ax.set_ylabel("tracking RMSE (N), participant's mean")
    ax.spines["top"].set_visible(False)
    ax.spines["right"].set_visible(False)
    ax.legend(frameon=False, loc="best")
    return fig


def speed_figure(trade: TargetSpeedTrade, folder: Path) -> bytes:
    """The trade's figure, saved as ``target_speed`` in ``folder``; its PNG."""
    return save(_figure(trade), folder, "target_speed")


def _follow_rows(stats: pd.DataFrame, metrics: Sequence[Metric]) -> str:
    rows = []
    by_metric = stats.set_index("metric")
    for m in follow_measures(metrics):
        if m.participant_exported not in by_metric.index:
            continue
        r = by_metric.loc[m.participant_exported]
        hl = f"{fmt(r['hl_estimate'])} [{fmt(r['hl_ci_low'])}, {fmt(r['hl_ci_high'])}]"
        rows.append(f"<tr><td class=\"m\">{html.escape(m.label)}</td><td>{fmt(r['median_off'])}</td>"
                    f"<td>{fmt(r['median_on'])}</td><td>{hl}</td><td>{int(r['n'])}</td><td>{fmt_p(r['p_value'])}"
                    f"</td><td>{html.escape(str(r['method']))}</td></tr>")
    return "".join(rows)


def _test_row(trade: TargetSpeedTrade) -> str:
    r = trade.result
    return (f"Across participants, the slope with haptics OFF has median {fmt(r.median_off)} s and ON "
            f"{fmt(r.median_on)} s; paired Wilcoxon signed-rank test ON vs OFF ({plural(r.n_used, 'ranked pair')}, "
            f"method {html.escape(r.method or 'none')}): p = {fmt_p(r.p_value)}, Hodges–Lehmann shift "
            f"{fmt(r.hl_estimate)} s [{fmt(r.hl_ci_low)}, {fmt(r.hl_ci_high)}]"
            + (f" ({html.escape(r.note)})" if r.note else "") + ".")


def tracking_body(trade: TargetSpeedTrade | None, stats: pd.DataFrame, metrics: Sequence[Metric],
                  png: bytes | None) -> str:
    """The section below its heading ("" when the study's target does not move: no trade and no measure of
    following)."""
    follow = _follow_rows(stats, metrics)
    if trade is None and not follow:
        return ""
    family = listed([m.short for m in primary(metrics)]) if primary(metrics) else "none"
    out = []
    if follow:
        names = listed([m.short for m in follow_measures(metrics)])
        out.append(
            f"<p>How the force follows the target: {html.escape(names)}, one value per participant per mode (the "
            "mean of their trials in that mode), compared ON vs OFF by the paired Wilcoxon signed-rank test, each "
            f"with its own p (secondary measures, outside Holm's family of the {family_word(metrics)} primary "
            f"measures: {html.escape(family)}). The lag is the shift of the force that maximises its correlation "
            "with the target over the moving part of the trial (positive: the force follows late); the gain the "
            "least-squares slope of the force on the target there (1: excursions of the right size). Medians "
            "across participants; the Hodges–Lehmann shift ON − OFF with its interval (stats.csv has every "
            "number).</p>"
            '<div class="scroll"><table class="stats"><thead><tr><th>measure</th><th>median OFF</th>'
            "<th>median ON</th><th>HL shift ON − OFF [CI]</th><th>n</th><th>p</th><th>p method</th></tr></thead>"
            f"<tbody>{follow}</tbody></table></div>")
    if trade is not None:
        speeds = sorted(set(np.round(trade.by_target["target_speed_n_per_s"], 6)))
        out.append(
            "<h3>Tracking error against the target's speed</h3>"
            f"<p>The protocol's profiles give the targets {len(speeds)} speeds ("
            f"{', '.join(f'{s:.3g}' for s in speeds)} N/s: the mean |dF*/dt| where the target moves). For each "
            "participant and mode, the mean RMSE of each target's trials against its speed, and the least-squares "
            "slope of that error on the speed (s: N of RMSE per N/s of speed) -- one value per participant per "
            f"mode. {_test_row(trade)} A steeper slope: faster targets cost more accuracy. No p-value here treats "
            "trials as independent; target_speed.csv, target_speed_slopes.csv and target_speed_test.csv have "
            "every number.</p>"
            + (f"<figure>{img(png, 'tracking RMSE against target speed per mode')}</figure>"
               '<p class="caption">Thin lines: each participant; thick: the mean across participants.</p>'
               if png else ""))
    return "\n".join(out)


@dataclass(frozen=True, slots=True)
class _Tracking:
    """The section (:class:`analysis.report.task_sections.TaskSection`) of force tracking."""

    kinds: tuple[str, ...] = ("force_tracking",)

    def build(self, given: SectionInput, folder: Path) -> SectionOutput:
        """The trade of the sessions' error against their targets' speed (none: the target holds, or fewer than two
        speeds) and the measures of following from the core's tests."""
        trade = (target_speed_trade(given.trials, given.study.task_of, zero_method=given.zero_method,
                                    confidence=given.confidence) if len(given.trials) else None)
        png = speed_figure(trade, folder / "figures") if trade is not None else None
        body = tracking_body(trade, given.stats, given.study.metrics, png) if len(given.stats) else ""
        return SectionOutput(TITLE, body, tracking_tables(trade) if trade is not None else {})


#: The section of force tracking's kind.
SECTION = _Tracking()
