"""What every column of every CSV the report writes means: the codebook, one table in code.

Each :class:`Column` (:mod:`analysis.reading.codebook_columns`, the table) names a column as it appears in the
CSV files, what it means, its unit, its type and how far it is rounded; the metrics' columns come from the metric
registry (:mod:`protocol.metrics`).  :func:`export` turns an analysis table into the file's form (the exported
names, rounded values) and :func:`codebook_frame` lists, for every file written, each column with its entry --
that list is ``codebook.csv``.  A column without an entry is written with an empty description, which the test
of the report refuses; to add a column that is not a metric's, add one line to :data:`COLUMNS`.

Conventions of the exported files
---------------------------------
* Units are the last part of a name: ``_s`` seconds, ``_ms`` milliseconds, ``_N`` newtons (a capital
  N, the SI symbol, so it cannot be read as a count); counts start with ``n_``
  (or are called ``n``).  Inside the analysis code and the database the
  newton suffix is ``_n``; only the exported files spell it ``_N``.
* Trials are numbered from 1 (``trial_number``), as the experimenter's window
  shows them; the database's ``trial_index`` is ``trial_number − 1``.
* Numbers are rounded to what the rig resolves: forces to 0.1 mN, times to the
  1 ms sample period, p-values to 4 significant digits, other statistics to 4
  decimals.  Nothing is rounded before the statistics are computed.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

import numpy as np
import pandas as pd

from analysis.reading.codebook_annotations import ANNOTATION_COLUMNS
from analysis.reading.codebook_columns import (
    _STATS,
    DIFFERENCE_DECIMALS,
    STATS_CSV_COLUMNS,
    Column,
    metric_words,
    participant_measures,
    task_column,
)
from analysis.reading.codebook_columns import COLUMNS as _TABLE_COLUMNS
from analysis.reading.codebook_groups import GROUP_COLUMNS
from analysis.reading.codebook_within import WITHIN_COLUMNS
from protocol.metrics import METRICS, Metric, tested
from protocol.tasks.registry import TASKS

__all__ = [
    "COLUMNS",
    "DIFFERENCE_DECIMALS",
    "DIFF_MEASURES",
    "STATS_CSV_COLUMNS",
    "WIDE_MEASURES",
    "Column",
    "codebook_frame",
    "export",
    "exported_name",
    "label",
    "lookup",
    "metric_words",
    "p_text",
    "wide_name",
]


#: Every entry: the trials, participants, tests and record's, then the within-participant analyses'.
COLUMNS: tuple[Column, ...] = _TABLE_COLUMNS + WITHIN_COLUMNS
#: The long-format measures that participants_wide.csv spreads into an OFF and an ON column.
WIDE_MEASURES: tuple[str, ...] = ("n_trials", *participant_measures())
#: The tested measures (participants.csv columns): participants_wide.csv has each one's ON − OFF difference too.
DIFF_MEASURES: tuple[str, ...] = tuple(m.participant_exported for m in tested(METRICS))
#: The unit parts of an exported name (its last parts).
_UNITS = {"s", "N", "ms"}


def wide_name(name: str, mode: str) -> str:
    """The participants_wide.csv column of measure ``name`` in haptic mode ``mode``: ``rmse_N`` → ``rmse_off_N``
    (the mode before the unit, ``abs_impulse_N_s`` → ``abs_impulse_off_N_s``)."""
    parts = name.split("_")
    k = len(parts)
    while k > 1 and parts[k - 1] in _UNITS:
        k -= 1
    return "_".join((*parts[:k], mode, *parts[k:]))


def _wide_columns() -> tuple[Column, ...]:
    out = [Column(c.name, c.description, c.unit, c.type, c.label, ("participants_wide.csv",), "", c.decimals,
                  c.significant)
           for c in COLUMNS if c.name in ("participant_code", "participant_number")]
    for name in WIDE_MEASURES:
        base = next(c for c in COLUMNS if c.name == name and (not c.files or "participants.csv" in c.files))
        for mode in ("off", "on"):
            out.append(Column(wide_name(name, mode), f"haptics {mode.upper()}: {base.description}", base.unit,
                              base.type, f"{base.label or name} {mode.upper()}", ("participants_wide.csv",), "",
                              base.decimals, base.significant))
    for name in DIFF_MEASURES:
        base = next(c for c in COLUMNS if c.name == name and (not c.files or "participants.csv" in c.files))
        out.append(Column(wide_name(name, "diff"), f"ON − OFF of {name}, rounded to {DIFFERENCE_DECIMALS} decimals as "
                          "the report's test rounds the differences before ranking: a one-sample Wilcoxon "
                          "signed-rank test of this column (JASP, SPSS) gives stats.csv's statistic and p; ON − OFF "
                          "computed from the rounded OFF and ON columns may not (0.6 − 0.4 ≠ 0.4 − 0.2 in floating "
                          "point, so equal differences stop tying)", base.unit, "number", f"{base.label or name} "
                          "ON − OFF", ("participants_wide.csv",), "", DIFFERENCE_DECIMALS))
    return tuple(out)


_ALL = COLUMNS + _wide_columns() + ANNOTATION_COLUMNS + GROUP_COLUMNS
#: analysis name -> exported name
_RENAMED: dict[str, str] = {c.source: c.name for c in COLUMNS if c.source}


def exported_name(name: str) -> str:
    """The exported name of an analysis column or measure (``rmse_n`` → ``rmse_N``); others unchanged."""
    return _RENAMED.get(name, name)


def lookup(file: str, column: str) -> Column | None:
    """The entry describing ``column`` of ``file`` (a file-specific entry first), or None."""
    general = None
    for c in _ALL:
        if c.name == column:
            if file in c.files:
                return c
            if not c.files and general is None:
                general = c
    if general is None:  # a task registered at run time (a lab's own) describes its parameters itself
        general = next((task_column(p) for cls in TASKS.values() for p in cls.described if p.name == column), None)
    return general


def _round(values: pd.Series, c: Column) -> pd.Series:
    if c.type != "number" or not pd.api.types.is_numeric_dtype(values) or pd.api.types.is_bool_dtype(values):
        return values
    x = values.to_numpy(dtype=np.float64)
    if c.decimals is not None:
        return pd.Series(np.round(x, c.decimals), index=values.index)
    if c.significant is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            mag = np.floor(np.log10(np.abs(x)))
        digits = np.where(np.isfinite(mag), c.significant - 1 - mag, 0).astype(np.int64)
        out = [v if not math.isfinite(v) or v == 0 else round(v, int(d))
               for v, d in zip(x.tolist(), digits.tolist(), strict=True)]
        return pd.Series(out, index=values.index, dtype=np.float64)
    return values


def export(frame: pd.DataFrame, file: str, *, rounded: bool = True) -> pd.DataFrame:
    """``frame`` as ``file`` is written: exported names (also as values of ``metric``) and rounded numbers.

    ``rounded=False``: the same table with every number as computed, for a page that rounds each number once,
    from the unrounded value, as it shows it (a number rounded for the file and again for the page can differ from
    the same number rounded once: -0.02154 is -0.0215 in the file, which shows as -0.021, not -0.022).

    Trial indices become 1-based trial numbers; a tests' file (``stats.csv``, ``stats_by_target.csv``, tables
    of :func:`analysis.stats.holm.results_frame`) gets ``n`` (the pairs ranked) and :data:`STATS_CSV_COLUMNS`
    first (after ``target_label``, in a table by target).
    """
    out = frame.rename(columns=_RENAMED)
    if file in _STATS:
        out.insert(1, "n", out["n_used"])
        first = ["target_label", *STATS_CSV_COLUMNS] if "target_label" in out.columns else list(STATS_CSV_COLUMNS)
        out = out[[*first, *(c for c in out.columns if c not in first)]]
    if "trial_index" in frame.columns:
        out["trial_number"] = frame["trial_index"].astype(np.int64) + 1
    if "metric" in out.columns:
        out["metric"] = out["metric"].map(exported_name)
    for name in out.columns:
        c = lookup(file, name)
        if c is not None and rounded:
            out[name] = _round(out[name], c)
    return out


def codebook_frame(files: Mapping[str, Iterable[str]], metrics: Sequence[Metric] | None = None,
                   described: Mapping[tuple[str, str], tuple[str, str, str]] | None = None) -> pd.DataFrame:
    """``codebook.csv``: one row per (file, column) of the files written, in file and column order.

    ``metrics`` are the study's (its tasks'), which the descriptions of the tests' columns name (the measures
    tested, Holm's family: :func:`metric_words`; None: in general words).  A column without an entry in
    :data:`COLUMNS` gets an empty description (the report's test refuses that), unless ``described`` -- (file,
    column) → (type, unit, description), a study's own columns such as its covariates -- describes it.
    """
    words = metric_words(metrics)
    rows = []
    for file, columns in files.items():
        for name in columns:
            own = (described or {}).get((file, name))
            if own is not None:
                rows.append({"file": file, "column": name, "type": own[0], "unit": own[1], "description": own[2]})
                continue
            c = lookup(file, name)
            rows.append({"file": file, "column": name, "type": c.type if c else "",
                         "unit": c.unit if c else "", "description": c.described(words) if c else ""})
    return pd.DataFrame(rows, columns=["file", "column", "type", "unit", "description"])


def label(file: str, column: str) -> str:
    """Short table heading of a column (its name if it has none)."""
    c = lookup(file, column)
    return (c.label or c.name) if c is not None else column


def p_text(v: object) -> str:
    """A p-value as the CSV files, the terminal, the page and the figures give it: 4 significant digits (an exact
    p of 1/32 is ``0.03125`` everywhere, not ``0.0312`` on the page or ``0.031`` under a figure), ``< 0.0001`` below
    that, ``–`` when there is none."""
    if not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(float(v)):
        return "–"
    f = float(v)
    return "< 0.0001" if f < 1e-4 else f"{f:.4g}"
