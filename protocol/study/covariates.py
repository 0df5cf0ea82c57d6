"""Who the participants are, pseudonymously: the covariates a protocol declares, their values checked.

A protocol file declares what it collects about each participant in ``[[covariates]]`` tables (none by default:
the paper's protocol asks nothing about the person).  Each is typed -- a ``category`` with its levels, an
``integer`` or a ``float`` with its range -- and optional unless the protocol says ``required = true``::

    [[covariates]]
    name = "group"                       # the column in participants.csv (lower case, digits, _)
    kind = "category"
    levels = ["novice", "resident", "surgeon"]
    required = true
    label = "Surgical experience"        # what the registration form asks (default: the name)

    [[covariates]]
    name = "robotic_hours"
    kind = "float"
    min = 0
    max = 10000
    unit = "h"

A value is given where a participant is registered (the GUI's form, ``run --covariate``) and stored with the
participant, in the transaction that stores their first session (:mod:`protocol.storage.annotations`).  Every
check here raises one line naming the field, the value and what is allowed.

Nothing identifying belongs here: a name, a date of birth or an e-mail address is not a covariate (age is asked
as a band, a category).  The declaration cannot stop a lab from asking for one, so the guide says it
(docs/study-design.md, *Participants described*).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from foundation.errors import InputRefused
from pipeline.settings.tomlfields import Fields, show

__all__ = [
    "COVARIATE_KINDS",
    "Covariate",
    "CovariateError",
    "CovariateValue",
    "checked_values",
    "covariates_from_tables",
    "parse_assignment",
    "simulated_values",
]

#: The kinds of covariate a protocol may declare.
COVARIATE_KINDS = ("category", "integer", "float")
#: A covariate's stored value: a level's name, a whole number or a real number.
CovariateValue = str | int | float
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,31}\Z")
#: Column names the report's participant tables use already: a covariate may not take one.
RESERVED = frozenset({
    "participant_code", "participant_number", "participant", "code", "haptic_mode", "session_id", "kind", "seed",
    "trial_number", "target_label", "outcome", "success", "error_window", "database", "n_trials", "n_success",
    "success_rate",
})
_MAX_LEVELS = 32
_LEVEL_CHARS = 40


class CovariateError(InputRefused):
    """A covariate's value is not what the protocol declares; the message names it, the value and what is allowed."""


@dataclass(frozen=True, slots=True)
class Covariate:
    """One declared covariate.

    Attributes
    ----------
    name
        Its column name (``participants.csv``, the codebook).
    kind
        ``category``, ``integer`` or ``float``.
    levels
        A category's levels, in the order the form lists them.
    lo, hi
        A number's inclusive range.
    required
        A participant cannot be registered without it.
    label, unit
        What the registration form asks, and the number's unit ("" none).
    """

    name: str
    kind: str
    levels: tuple[str, ...] = ()
    lo: float = 0.0
    hi: float = 0.0
    required: bool = False
    label: str = ""
    unit: str = ""

    @property
    def question(self) -> str:
        """What the form asks (the label, else the name in words: ``age_band`` → *Age band*)."""
        return self.label or self.name.replace("_", " ").capitalize()

    def allowed(self) -> str:
        """What a value may be, in words (the end of every refusal)."""
        if self.kind == "category":
            return f"one of {', '.join(self.levels)}"
        unit = f" {self.unit}" if self.unit else ""
        if self.kind == "integer":
            return f"a whole number from {int(self.lo)} to {int(self.hi)}{unit}"
        return f"a number from {self.lo:g} to {self.hi:g}{unit}"

    def described(self) -> str:
        """The codebook's words for it."""
        need = "required" if self.required else "optional"
        return f"{self.question} ({self.kind}, {need}): {self.allowed()}"

    def value(self, v: Any, field: str = "") -> CovariateValue:
        """``v`` (typed, or the text a form or a command line gives) as this covariate's value.

        Raises
        ------
        CovariateError
            One line: ``covariate NAME = VALUE: must be …``.
        """
        where = field or f"covariate {self.name}"

        def refuse() -> CovariateError:
            return CovariateError(f"{where} = {show(v)}: must be {self.allowed()}")

        if isinstance(v, bool):
            raise refuse()
        if self.kind == "category":
            if not isinstance(v, str) or v.strip() not in self.levels:
                raise refuse()
            return v.strip()
        number: float | int
        if isinstance(v, str):
            text = v.strip()
            try:
                number = int(text) if self.kind == "integer" else float(text)
            except ValueError:
                raise refuse() from None
        elif isinstance(v, int | float):
            number = v
        else:
            raise refuse()
        if self.kind == "integer":
            if isinstance(number, float) and not number.is_integer():
                raise refuse()
            if not self.lo <= number <= self.hi:
                raise refuse()
            return int(number)
        if not (math.isfinite(float(number)) and self.lo <= number <= self.hi):
            raise refuse()
        return float(number)

    def to_dict(self) -> dict[str, Any]:
        """The declaration as the file writes it (stored with each session's protocol)."""
        d: dict[str, Any] = {"name": self.name, "kind": self.kind}
        if self.kind == "category":
            d["levels"] = list(self.levels)
        else:
            d["min"], d["max"] = (int(self.lo), int(self.hi)) if self.kind == "integer" else (self.lo, self.hi)
        d["required"] = self.required
        if self.label:
            d["label"] = self.label
        if self.unit:
            d["unit"] = self.unit
        return d


def _one(f: Fields, field: str, t: Any, taken: Iterable[str]) -> Covariate:
    t = f.table(field, t, {"name", "kind", "levels", "min", "max", "required", "label", "unit"})
    f.required(t, field, "name", "every covariate needs a name (lower case letters, digits, _)")
    name = f.string(f"{field}.name", t["name"], pattern=_NAME,
                    what="a lower-case name of 1–32 letters, digits or _ starting with a letter (e.g. group)")
    if name in RESERVED:
        raise f.fail(f"{field}.name", name,
                     f"is a column the report already has; reserved: {', '.join(sorted(RESERVED))}")
    if name in taken:
        raise f.fail(f"{field}.name", name, "is declared twice: covariate names must be unique")
    f.required(t, field, "kind", f"allowed kinds: {', '.join(COVARIATE_KINDS)}")
    kind = f.choice(f"{field}.kind", t["kind"], COVARIATE_KINDS)
    required = f.boolean(f"{field}.required", t.get("required", False))
    label = f.string(f"{field}.label", t["label"]) if "label" in t else ""
    if kind == "category":
        for key in ("min", "max", "unit"):
            if key in t:
                raise f.fail(f"{field}.{key}", t[key], "a category has levels, not a range or a unit")
        f.required(t, field, "levels", "a category needs its levels, e.g. [\"novice\", \"resident\", \"surgeon\"]")

        def level(lf: str, v: Any) -> str:
            return f.string(lf, v, what=f"a level's name of 1–{_LEVEL_CHARS} characters")

        levels = f.list_of(f"{field}.levels", t["levels"], level, min_len=2, max_len=_MAX_LEVELS,
                           what=f"a list of 2 to {_MAX_LEVELS} level names")
        if len(set(levels)) != len(levels) or any(len(x) > _LEVEL_CHARS for x in levels):
            raise f.fail(f"{field}.levels", levels, f"levels must be distinct, each at most {_LEVEL_CHARS} characters")
        return Covariate(name, kind, tuple(levels), required=required, label=label)
    if "levels" in t:
        raise f.fail(f"{field}.levels", t["levels"], f"an {kind} has a range (min, max), not levels")
    for key in ("min", "max"):
        f.required(t, field, key, f"an {kind} covariate needs its range: min and max")
    lo: float
    hi: float
    if kind == "integer":
        lo = f.integer(f"{field}.min", t["min"], lo=-(10**9), hi=10**9)
        hi = f.integer(f"{field}.max", t["max"], lo=-(10**9), hi=10**9)
    else:
        lo = f.number(f"{field}.min", t["min"], lo=-1e12, hi=1e12, lo_open=False)
        hi = f.number(f"{field}.max", t["max"], lo=-1e12, hi=1e12, lo_open=False)
    if hi <= lo:
        raise f.fail(f"{field}.max", t["max"], f"must be greater than {field}.min = {show(t['min'])}")
    unit = f.string(f"{field}.unit", t["unit"], what="a unit's name (e.g. years)") if "unit" in t else ""
    return Covariate(name, kind, lo=float(lo), hi=float(hi), required=required, label=label, unit=unit)


def covariates_from_tables(f: Fields, v: Any) -> tuple[Covariate, ...]:
    """The protocol file's ``[[covariates]]`` (absent: none), each checked (one line naming the field)."""
    if v is None:
        return ()
    if not isinstance(v, list) or len(v) > 32:
        raise f.fail("covariates", v, "must be a list of at most 32 [[covariates]] tables")
    out: list[Covariate] = []
    for i, t in enumerate(v):
        out.append(_one(f, f"covariates[{i}]", t, [c.name for c in out]))
    return tuple(out)


def checked_values(declared: Sequence[Covariate], given: Mapping[str, Any]) -> dict[str, CovariateValue]:
    """The values ``given`` (by name; text or typed), checked against the declarations, in declaration order.

    An empty value ("" or None) is no value.  Raises :class:`CovariateError` (one line) for a name the protocol
    does not declare, a value outside what is declared, or a required covariate without a value.
    """
    names = [c.name for c in declared]
    for name in given:
        if name not in names:
            allowed = f"it declares {', '.join(names)}" if names else "it declares none"
            raise CovariateError(f"covariate {name} = {show(given[name])}: the protocol declares no such covariate "
                                 f"({allowed})")
    out: dict[str, CovariateValue] = {}
    for c in declared:
        v = given.get(c.name)
        if v is None or (isinstance(v, str) and not v.strip()):
            if c.required:
                raise CovariateError(f"covariate {c.name} = (none): required by the protocol; must be {c.allowed()}")
            continue
        out[c.name] = c.value(v)
    return out


def parse_assignment(text: str) -> tuple[str, str]:
    """``NAME=VALUE`` (a command line's ``--covariate``) as (name, value text); one line when there is no ``=``."""
    name, eq, value = text.partition("=")
    if not eq or not name.strip():
        raise CovariateError(f"--covariate = {text!r}: must be NAME=VALUE (e.g. group=novice)")
    return name.strip(), value.strip()


def simulated_values(declared: Sequence[Covariate], study_seed: int, number: int) -> dict[str, CovariateValue]:
    """A simulated participant's covariates, drawn from the declarations: the same study seed and participant
    number give the same values.

    The rule (documented in docs/study-design.md): a category's level uniformly among its levels; an integer
    uniformly among the whole numbers of its range; a float uniformly in its range, to 0.1.  Every declared
    covariate gets a value.  The draws come from a stream of their own (the seed, the number and 44), so the rig,
    the participant's hand and the schedule draw exactly what they drew before covariates existed.
    """
    rng = np.random.default_rng([study_seed, number, 44])
    out: dict[str, CovariateValue] = {}
    for c in declared:
        if c.kind == "category":
            out[c.name] = c.levels[int(rng.integers(len(c.levels)))]
        elif c.kind == "integer":
            out[c.name] = int(rng.integers(int(c.lo), int(c.hi) + 1))
        else:
            out[c.name] = min(max(round(float(rng.uniform(c.lo, c.hi)), 1), c.lo), c.hi)
    return out
