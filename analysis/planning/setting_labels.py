"""Labels that tell apart every setting a sweep's tables and figures hold.

``f"{v:g}"`` writes six significant digits: two settings that differ below them (``f_scale = 7`` and
``7.0000001``) would be labelled alike in every table and figure, and a reader could not say which row is which.
A swept setting's values are written with the fewest significant digits, six at least, that give each distinct
value its own label; 17 always do (a double round-trips in 17 significant digits).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

__all__ = ["setting_formats", "value_format"]

#: ``:g``'s own precision, kept where it already tells the values apart (the labels users know).
_FEWEST_DIGITS = 6
#: Significant digits that tell apart any two distinct doubles.
_ROUND_TRIP_DIGITS = 17


def value_format(values: Iterable[Any]) -> Callable[[Any], str]:
    """A formatter that writes each of ``values`` with the fewest significant digits telling them apart."""
    distinct = {float(v) for v in values}
    digits = next(d for d in range(_FEWEST_DIGITS, _ROUND_TRIP_DIGITS + 1)
                  if len({f"{v:.{d}g}" for v in distinct}) == len(distinct))
    return lambda v: f"{float(v):.{digits}g}"


def setting_formats(rows: Mapping[str, Iterable[Any]], names: Sequence[str]) -> dict[str, Callable[[Any], str]]:
    """One formatter per swept setting ``names``, from the values ``rows[name]`` holds (a frame's columns)."""
    return {name: value_format(rows[name]) for name in names}
