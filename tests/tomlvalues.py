"""Hypothesis strategies for whatever a TOML file can hold, and a helper to put one value into a parsed file."""

from __future__ import annotations

import copy
from typing import Any

from hypothesis import strategies as st

#: Every kind of value tomllib returns: booleans, integers of any size, floats (inf, nan), strings,
#: dates and times, and arrays and tables of them.
TOML_SCALARS = st.one_of(
    st.booleans(),
    st.integers(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.sampled_from([0, 1, -1, 2**63, -(2**63) - 1, 10**400]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.sampled_from(["", " ", "on", "1", "true", "GENTLE", "10.0.0.1", "\n"]),
    st.datetimes(),
    st.dates(),
    st.times(),
)
TOML_VALUES = st.recursive(
    TOML_SCALARS,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=8,
)


def replaced(d: dict[str, Any], path: tuple[str | int, ...], value: Any) -> dict[str, Any]:
    """A deep copy of ``d`` with the item at ``path`` (keys and list indices) set to ``value``."""
    out = copy.deepcopy(d)
    node: Any = out
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return out
