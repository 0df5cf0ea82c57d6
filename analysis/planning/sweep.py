"""A sweep of the pipeline's settings over simulated studies: the cache, the tables and the summary (``haptic-study
sweep``).

A sweep runs, for every setting of its grid (one value of each swept setting) and every study ``k`` of
``--studies``, a complete simulated study (:mod:`study_app.headless.sim_trials`): the same participants for
every setting, so the settings are compared on paired data.  Each finished cell (setting, study) is one line of
the output folder's ``cells.jsonl``, keyed by everything that decides its rows (:func:`cell_key`), so a run that
stops is completed by the same command, and a cell already run is never run again.

From the cells: ``sweep.csv`` (tidy: the swept settings, ``study``, ``metric``, ``off``, ``on``, ``change``; each
study's group means of the participants' values, :func:`analysis.planning.sim_study.summarise_study`) and
``sweep_summary.csv`` (per setting and metric the mean over studies with a 95 % t-interval over the study means),
the figures (:mod:`analysis.planning.sweep_figures`) and ``sweep.md``, which opens with the caveat: these numbers are a
prediction of the simulated participant model, not a measurement.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from analysis.planning.setting_labels import setting_formats
from analysis.planning.sim_study import (
    SIMULATED,
    TrialRow,
    censored_key,
    measure_labels,
    row_metrics,
    summarise_study,
    trial_row_from_dict,
    trial_row_to_dict,
)
from foundation.platform_support.files import O_NOFOLLOW
from protocol.metrics import METRICS as ALL_METRICS
from protocol.metrics import Metric

__all__ = [
    "CACHE_FILE", "FILTER_NOTE", "METRICS", "SWEEP_MARKER", "SweepCell", "append_cell", "caveat", "cell_key",
    "is_cache_file",
    "protocol_digest", "read_cache", "summary_frame", "sweep_frame", "t_interval", "write_sweep",
]

#: The output folder's marker (:mod:`foundation.outdir`).
SWEEP_MARKER = ".haptic-study-sweep"
#: The cache of finished cells, kept in the output folder (never replaced by ``--force``).
CACHE_FILE = "cells.jsonl"
#: The measures a sweep may report (:data:`analysis.planning.sim_study.SIMULATED`: a sweep reports those its
#: protocol's task produces), in order, with their labels; a success-only one (TCT) in both readings: over
#: successful trials (with their count, ``n_trials_*``) and over every trial, a failure at the cap (the report's
#: default).
METRICS: dict[str, str] = measure_labels(SIMULATED)


@dataclass(frozen=True)
class SweepCell:
    """One setting of the grid in one study: its trial rows."""

    settings: dict[str, float]
    study: int
    rows: list[TrialRow]


def is_cache_file(name: str) -> bool:
    """Whether a file of the output folder is the sweep's cache (kept, reused, never replaced)."""
    return name == CACHE_FILE


def protocol_digest(protocol_json: str) -> str:
    """A short digest of the protocol a cell ran (part of its key)."""
    return hashlib.sha256(protocol_json.encode("utf-8")).hexdigest()[:16]


def cell_key(settings: Mapping[str, float], study: int, participants: int, seed: int, model_version: str,
             protocol: str) -> str:
    """What decides a cell's rows, as one canonical string: every pipeline setting (all of them, so a grid that
    does not sweep a setting shares cells with one that sweeps it through the same value), the study number, the
    participants, the seed, the participant model's version and the protocol's digest."""
    return json.dumps({"settings": {k: float(v) for k, v in sorted(settings.items())}, "study": study,
                       "participants": participants, "seed": seed, "model_version": model_version,
                       "protocol": protocol}, sort_keys=True)


def read_cache(path: str | os.PathLike[str], metrics: Sequence[Metric]) -> dict[str, list[TrialRow]]:
    """The cells in a cache file by key (none when there is no file), their rows with these ``metrics`` (the
    protocol's task's, :func:`analysis.planning.sim_study.sim_metrics`); a line cut short by a killed run is
    skipped (its cell runs again), and so is one without a metric (written before it existed)."""
    out: dict[str, list[TrialRow]] = {}
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        return out
    for line in text.splitlines():
        try:
            record = json.loads(line)
            out[str(record["key"])] = [trial_row_from_dict(r, metrics) for r in record["rows"]]
        except (ValueError, KeyError, TypeError):
            continue
    return out


def append_cell(path: str | os.PathLike[str], key: str, rows: Sequence[TrialRow]) -> None:
    """Append one finished cell to the cache (created owner-only; never through a link)."""
    line = json.dumps({"key": key, "rows": [trial_row_to_dict(r) for r in rows]}, separators=(",", ":")) + "\n"
    flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | O_NOFOLLOW  # (0 where the OS has none: platform_support)
    fd = os.open(path, flags, 0o600)
    try:
        size = os.fstat(fd).st_size
        if size:  # a line cut short by a killed run: start on a line of its own
            with open(path, "rb") as f:
                f.seek(size - 1)
                if f.read(1) != b"\n":
                    line = "\n" + line
        os.write(fd, line.encode("utf-8"))
        os.fsync(fd)
    finally:
        os.close(fd)


#: What each measure can be (success a rate, the rest ≥ 0; the change ON/OFF − 1 of a measure ≥ 0 is ≥ −1): the
#: ends of a t-interval over a few studies can pass these, and are clipped to them (``sweep.md`` says so).
_BOUNDS: dict[str, tuple[float, float]] = {
    **{m.name: m.values for m in ALL_METRICS}, **{censored_key(m): m.values for m in ALL_METRICS if m.success_only}}
_CHANGE_BOUNDS = (-1.0, math.inf)
#: The yes/no outcomes, whose means are rates.
_RATES = {m.name for m in ALL_METRICS if m.boolean}


def t_interval(values: Sequence[float], level: float = 0.95,
               bounds: tuple[float, float] = (-math.inf, math.inf)) -> tuple[float, float, float]:
    """Mean and the two ends of the ``level`` t-interval of the mean (NaN ends with fewer than two values), the ends
    clipped to ``bounds``, the values the quantity can take."""
    from scipy.stats import t

    v = np.asarray([x for x in values if math.isfinite(x)], dtype=np.float64)
    if v.size == 0:
        return math.nan, math.nan, math.nan
    mean = float(v.mean())
    if v.size < 2:
        return mean, math.nan, math.nan
    half = float(t.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))
    return mean, max(bounds[0], mean - half), min(bounds[1], mean + half)


def _entered(rows: Sequence[TrialRow], metric: str, mode: str) -> int:
    """The trials of ``mode`` whose value entered ``metric``'s means (TCT over successful trials: the successes)."""
    mine = [r for r in rows if r.mode == mode]
    if metric not in {m.name for m in row_metrics(rows)}:  # a censored reading: every trial
        return len(mine)
    return sum(1 for r in mine if (v := r.values.get(metric)) is not None and math.isfinite(float(v)))


def sweep_frame(cells: Sequence[SweepCell], swept: Sequence[str], max_trial_s: float) -> pd.DataFrame:
    """sweep.csv: per cell and measure the study's OFF and ON group means, the change ON/OFF − 1 and the trials that
    entered each mode's means (``n_trials_off``, ``n_trials_on``: TCT over successful trials has the successes)."""
    records = []
    for cell in cells:
        s = summarise_study(cell.rows, max_trial_s)
        for metric in measure_labels(row_metrics(cell.rows)):  # the measures of the protocol's task
            records.append({**{k: cell.settings[k] for k in swept}, "study": cell.study, "metric": metric,
                            "off": s[metric]["off"], "on": s[metric]["on"], "change": s[metric]["change"],
                            "n_trials_off": _entered(cell.rows, metric, "off"),
                            "n_trials_on": _entered(cell.rows, metric, "on")})
    return pd.DataFrame.from_records(records, columns=[*swept, "study", "metric", "off", "on", "change",
                                                       "n_trials_off", "n_trials_on"])


def summary_frame(tidy: pd.DataFrame, swept: Sequence[str], paper: Mapping[str, float]) -> pd.DataFrame:
    """Per setting and measure: studies, and for OFF, ON and the change the mean over studies with its 95 %
    t-interval (over the study means); ``paper`` True on the paper's setting."""
    rows = []
    for key, grp in tidy.groupby([*swept, "metric"], sort=False):
        values = dict(zip([*swept, "metric"], key if isinstance(key, tuple) else (key,), strict=True))
        row: dict[str, Any] = {**values, "n_studies": int(grp["study"].nunique())}
        for mode in ("off", "on"):  # every study's trials that entered the means
            row[f"n_trials_{mode}"] = int(grp[f"n_trials_{mode}"].sum()) if f"n_trials_{mode}" in grp else 0
        for col in ("off", "on", "change"):
            bounds = _CHANGE_BOUNDS if col == "change" else _BOUNDS[str(values["metric"])]
            row[col], row[f"{col}_ci_low"], row[f"{col}_ci_high"] = t_interval(grp[col].tolist(), bounds=bounds)
        row["paper"] = all(float(values[k]) == float(paper[k]) for k in swept)
        rows.append(row)
    return pd.DataFrame(rows)


#: What a sweep of the filter window changes besides what the participant feels (docs/science.md §4.3).
FILTER_NOTE = ("The filter window also changes the task force every trial is judged on (success, TCT, RMSE and "
               "Max AE are computed from the filtered force, protocol/tasks/force_regulation.py), for haptics-OFF "
               "trials too: a change with the window is partly the measurement's, not only the participants'.")


def caveat(model_version: str, model_fit: str) -> str:
    """The sentence every sweep's summary opens with."""
    return (f"These results are a prediction of simulated participant model v{model_version} ({model_fit}), "
            "not a measurement: they say what the model predicts people would do with each setting.")


def _fmt(v: float, metric: str) -> str:
    if not math.isfinite(v):
        return "–"
    return f"{v:.2f}" if metric in _RATES else f"{v:.3f}"  # a rate, or a mean


def _ci(row: Mapping[str, Any], col: str, metric: str) -> str:
    lo, hi = row[f"{col}_ci_low"], row[f"{col}_ci_high"]
    if col == "change":
        mid = f"{row[col] * 100:+.0f} %" if math.isfinite(row[col]) else "–"
        return mid + (f" [{lo * 100:+.0f}, {hi * 100:+.0f}]" if math.isfinite(lo) else "")
    return _fmt(row[col], metric) + (f" [{_fmt(lo, metric)}, {_fmt(hi, metric)}]" if math.isfinite(lo) else "")


def summary_lines(summary: pd.DataFrame, swept: Sequence[str]) -> list[str]:
    """The summary as a Markdown table: one row per setting and measure (mean [95 % CI] over studies)."""
    head = [*swept, "measure", "OFF", "ON", "change ON/OFF", "studies", "trials OFF / ON"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    fmts = setting_formats(summary, swept)
    for r in summary.to_dict("records"):
        mark = " (paper)" if r["paper"] else ""
        cells = [f"{fmts[k](r[k])}{mark if i == 0 else ''}" for i, k in enumerate(swept)]
        cells += [METRICS[r["metric"]], _ci(r, "off", r["metric"]), _ci(r, "on", r["metric"]),
                  _ci(r, "change", r["metric"]), str(r["n_studies"]), f"{r['n_trials_off']} / {r['n_trials_on']}"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _front_words(front: Any) -> str:
    """sweep_front.png in words (:class:`analysis.planning.sweep_figures.Front`; None: the task has no front)."""
    return "no front: the protocol's task has none of the sweep's fronts" if front is None else front.words()


def write_sweep(folder: Path, *, tidy: pd.DataFrame, summary: pd.DataFrame, swept: Sequence[str],
                paper: Mapping[str, float], model_version: str, model_fit: str, header: Sequence[str]) -> list[str]:
    """Write sweep.csv, sweep_summary.csv, sweep.png, sweep_front.png and sweep.md into ``folder``; their names."""
    from analysis.planning.sweep_figures import front_figure, front_of, metrics_figure
    from analysis.plots.figures import save_one

    # the measures by the names of the report's CSVs and codebook (success_rate, rmse_N), not the runner's keys
    named = {m.name: m.participant_exported for m in ALL_METRICS}
    named.update({censored_key(m): str(m.censored) for m in ALL_METRICS if m.success_only})
    tidy.replace({"metric": named}).to_csv(folder / "sweep.csv", index=False, float_format="%.6g")
    summary.replace({"metric": named}).to_csv(folder / "sweep_summary.csv", index=False, float_format="%.6g")
    save_one(metrics_figure(summary, swept, paper, caveat(model_version, model_fit)), folder / "sweep.png")
    save_one(front_figure(summary, swept, caveat(model_version, model_fit)), folder / "sweep_front.png")
    md = ["# Pipeline settings sweep", "", f"**{caveat(model_version, model_fit)}**", "", *header, "",
          "Mean over studies [95 % t-interval over the study means, its ends clipped to what the measure can be: "
          "a rate 0–1, the rest ≥ 0, a change ≥ −100 %; with few studies the interval is wide]; each study's value "
          "is the mean over its participants of their own means (success: their success rate; TCT: over their "
          "successful trials only, n the successful trials of every study, and over every trial with a failure at "
          "the cap, the report's default). Change: ON/OFF − 1.  The paper's setting is marked (paper).",
          *(["", FILTER_NOTE] if "filter_window" in swept else []), "", *summary_lines(summary, swept), "",
          "Files: sweep.csv (per study), sweep_summary.csv (this table), sweep.png (the measures against the "
          f"setting), sweep_front.png ({_front_words(front_of(summary))}), cells.jsonl (the cache of finished "
          "cells).", ""]
    (folder / "sweep.md").write_text("\n".join(md), encoding="utf-8")
    return ["sweep.csv", "sweep_summary.csv", "sweep.png", "sweep_front.png", "sweep.md"]
