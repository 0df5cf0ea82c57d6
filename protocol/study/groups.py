"""A between-group design: which covariate divides the participants into groups, and how simulated ones are placed.

A protocol that compares groups of participants (novices against surgeons) says so in a ``[groups]`` table::

    [groups]
    by = "group"                        # a category covariate of [[covariates]]: the report compares its levels
    simulated = ["novice", "surgeon"]   # simulated participants: these levels, in turn (default: every level)
    experienced = ["surgeon"]           # levels a simulated participant plays with the experienced profile

``by`` is what ``report`` and ``power`` use (each group's haptic effect, the group × haptics interaction, the test
between groups: :mod:`analysis.stats.groups`).  ``simulated`` and ``experienced`` are read only where participants
are simulated (``haptic-study run``, ``power --simulated``): simulated participant k of a study gets a level by
:func:`simulated_level` (balanced: each run of ``len(simulated)`` participants holds every level once, in an order
drawn from the study seed), and one whose level is in ``experienced`` is simulated with the experienced profile
(:mod:`pipeline.sim.experience`).  A protocol without the table compares nothing and simulates as before.

Every check raises one line naming the field, the value and what is allowed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.settings.tomlfields import Fields
from protocol.study.covariates import Covariate, CovariateValue, simulated_values

__all__ = ["GroupDesign", "groups_from_table", "simulated_covariates", "simulated_level", "simulated_profile"]


@dataclass(frozen=True, slots=True)
class GroupDesign:
    """The protocol's ``[groups]``.

    Attributes
    ----------
    by
        The grouping covariate's name (a category).
    levels
        Its declared levels, in order: the groups, the first the reference of the interaction model.
    simulated
        The levels simulated participants are given, in turn.
    experienced
        The levels simulated with the experienced profile.
    """

    by: str
    levels: tuple[str, ...]
    simulated: tuple[str, ...]
    experienced: tuple[str, ...] = ()

    def profile(self, level: object) -> str:
        """The simulated participant's profile for a participant of ``level``: ``experienced`` or ``novice``."""
        return "experienced" if level in self.experienced else "novice"

    def to_dict(self) -> dict[str, Any]:
        """The table as the file writes it (stored with each session's protocol)."""
        return {"by": self.by, "simulated": list(self.simulated), "experienced": list(self.experienced)}


def groups_from_table(f: Fields, v: Any, covariates: Sequence[Covariate]) -> GroupDesign | None:
    """The protocol file's ``[groups]`` (absent: None), checked against its ``[[covariates]]``."""
    if v is None:
        return None
    t = f.table("groups", v, {"by", "simulated", "experienced"})
    categories = [c for c in covariates if c.kind == "category"]
    names = ", ".join(c.name for c in categories) or "none"
    f.required(t, "groups", "by", f"the category covariate that divides the participants (declared: {names})")
    by = f.string("groups.by", t["by"])
    declared = {c.name: c for c in covariates}
    if by not in declared:
        raise f.fail("groups.by", by, f"must name a category covariate the protocol declares (declared categories: "
                                      f"{names})")
    cov = declared[by]
    if cov.kind != "category":
        article = "an" if cov.kind == "integer" else "a"
        raise f.fail("groups.by", by, f"is {article} {cov.kind} covariate: groups need a category (declared "
                                      f"categories: {names})")

    def level_list(field: str, default: Sequence[str], min_len: int) -> tuple[str, ...]:
        if field not in t:
            return tuple(default)

        def level(lf: str, x: Any) -> str:
            return f.choice(lf, x, cov.levels, f"must be a level of {by}: {', '.join(cov.levels)}")

        got = f.list_of(f"groups.{field}", t[field], level, min_len=min_len, max_len=len(cov.levels),
                        what=f"a list of {min_len} to {len(cov.levels)} distinct levels of {by}")
        if len(set(got)) != len(got):
            raise f.fail(f"groups.{field}", got, "each level once")
        return tuple(got)

    simulated = level_list("simulated", cov.levels, 2)
    experienced = level_list("experienced", (), 1)
    return GroupDesign(by, cov.levels, simulated, experienced)


def simulated_level(design: GroupDesign, study_seed: int, number: int) -> str:
    """The level simulated participant ``number`` (1-based) of a study is given: participants 1..k, k+1..2k, ...
    (k the number of simulated levels) each hold every level once, in an order drawn from the study seed and the
    run's number, so any 2k participants are k of each kind (half and half for two levels)."""
    k = len(design.simulated)
    run, place = divmod(number - 1, k)
    order = np.random.default_rng([study_seed, run, 4402]).permutation(k)
    return design.simulated[int(order[place])]


def simulated_covariates(declared: Sequence[Covariate], design: GroupDesign | None, study_seed: int,
                         number: int) -> dict[str, CovariateValue]:
    """A simulated participant's covariates: drawn by :func:`protocol.study.covariates.simulated_values`, the
    grouping covariate's value placed by :func:`simulated_level` instead (no ``[groups]``: as drawn)."""
    values = simulated_values(declared, study_seed, number)
    if design is not None:
        values[design.by] = simulated_level(design, study_seed, number)
    return values


def simulated_profile(design: GroupDesign | None, covariates: Mapping[str, object]) -> str:
    """The simulated participant's profile for a participant with these covariates (``novice`` without
    ``[groups]``; otherwise :meth:`GroupDesign.profile` of their group)."""
    return "novice" if design is None else design.profile(covariates.get(design.by))
