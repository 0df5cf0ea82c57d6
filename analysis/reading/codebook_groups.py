"""The codebook's entries of the between-group files (written only when the protocol declares ``[groups]``:
:mod:`analysis.report.groups_report`).

``groups.csv`` holds each group's ON-vs-OFF tests, so its test columns mean what they mean in ``stats.csv`` and are
described by those entries; ``group_interaction.csv`` holds fixed effects as the other models' files do.
"""

from __future__ import annotations

import dataclasses

from analysis.reading.codebook_columns import COLUMNS as _TABLE_COLUMNS
from analysis.reading.codebook_columns import Column
from analysis.reading.codebook_within import WITHIN_COLUMNS

__all__ = ["GROUP_COLUMNS"]

_G = ("groups.csv",)
_GI = ("group_interaction.csv",)
_GT = ("group_tests.csv",)

_OWN: tuple[Column, ...] = (
    Column("group", "the group: a level of the protocol's grouping covariate ([groups] by)", type="text",
           files=(*_G, *_GT)),
    Column("n_participants", "participants of the group analysed", "count", "integer", files=_G),
    Column("model", "group_interaction: outcome ~ haptics_on × group + target (+ site), participant as the unit "
           "(see formula)", type="text", files=_GI),
    Column("term", "fixed effect: intercept, haptics_on (ON − OFF in the reference group), group_<level> (that "
           "group − the reference, OFF), haptics_on_x_group_<level> (the interaction: that group's ON − OFF effect "
           "minus the reference group's), target_<label> (that target − the lowest), site_<name>; empty when the "
           "model was not fitted", type="text", files=_GI),
    Column("formula", "the model, in formula notation (random effects in parentheses)", type="text", files=_GI),
    Column("reference", "the reference group: the first declared level with enough participants", type="text",
           files=_GT),
    Column("n_group", "participants of the group with an ON − OFF effect of the measure", "count", "integer",
           files=_GT),
    Column("n_reference", "participants of the reference group with an ON − OFF effect of the measure", "count",
           "integer", files=_GT),
    Column("median_effect_group", "median over the group's participants of their ON − OFF difference",
           "unit of the measure (see metric)", files=_GT, decimals=6),
    Column("median_effect_reference", "median over the reference group's participants of their ON − OFF difference",
           "unit of the measure (see metric)", files=_GT, decimals=6),
    Column("u_statistic", "Mann–Whitney U of the group's effects against the reference group's", files=_GT,
           decimals=4),
    Column("p_value", "two-sided p of the Mann–Whitney U test (each comparison its own p)", "probability", files=_GT,
           significant=4),
    Column("rank_biserial", "rank-biserial correlation 2U/(n_group · n_reference) − 1; positive: the group's ON − "
           "OFF effects are larger (more positive) than the reference group's", files=_GT, decimals=4),
    Column("test", "the test: Mann–Whitney U, two-sided, on the per-participant ON − OFF effects", type="text",
           files=_GT),
    Column("method", "exact (no ties), or the normal approximation with tie and continuity corrections",
           type="text", files=_GT),
    Column("computable", "false when no test was possible (see note)", type="boolean", files=_GT),
    Column("note", "why the comparison was not made; empty otherwise", type="text", files=_GT),
    Column("metric", "the measure compared (participants.csv column)", type="text", files=_GT),
)


def _like(files: tuple[str, ...], source: str, skip: set[str]) -> tuple[Column, ...]:
    """The entries of ``source``'s columns, for ``files`` (the same meaning), except those in ``skip``."""
    return tuple(dataclasses.replace(c, files=files) for c in (*_TABLE_COLUMNS, *WITHIN_COLUMNS)
                 if source in c.files and c.name not in skip)


#: Every entry of the between-group files.
GROUP_COLUMNS: tuple[Column, ...] = (
    _OWN
    + _like(_G, "stats.csv", {"group", "n_participants"})
    + _like(_GI, "learning_models.csv", {"model", "term"})
)
