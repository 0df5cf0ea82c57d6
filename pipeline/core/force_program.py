"""A force the loop renders as commanded, not as the sensor measures it: a program over time since it was given.

The paper's loop renders what the F/T sensor measures (Algorithm 1); a psychophysics trial (force discrimination,
issue 43) asks the device to *present* a force: two plateaus, one after the other.  A :class:`ForceProgram` is that
command as plain data (it crosses the pipe to a loop in its own process, and is logged for replay): knots
``(t_s, force_n)``, linear between them and the last one held, along the haptic frame's
``z`` axis.  The loop takes it with :class:`pipeline.runtime.loop_messages.CommandForce` and feeds its value at each
tick to the framework's safety stage in place of the scaled sensor force
(:meth:`pipeline.force.framework.HapticFramework.step_commanded`): clamped to ``min(f_max, device limit)``,
slew-limited, faded in and out, ramped to zero by a fault -- the same guard as every other force it renders.
"""

from __future__ import annotations

import itertools
import math
from bisect import bisect_right
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["ForceProgram", "check_knots", "knot_value"]

Knots = tuple[tuple[float, float], ...]


def check_knots(knots: Knots, owner: str, what: str) -> None:
    """Refuse knots that do not start at 0 s, increase and hold finite forces (``ValueError`` naming ``owner``)."""
    if not knots:
        raise ValueError(f"{owner}.knots is empty: {what} needs at least one (t_s, force_n) knot")
    times = [t for t, _ in knots]
    if times[0] != 0.0 or any(not b > a for a, b in itertools.pairwise(times)):
        raise ValueError(f"{owner}.knots times = {times!r}: must start at 0 s and increase")
    if not all(math.isfinite(f) for _, f in knots):
        raise ValueError(f"{owner}.knots forces = {[f for _, f in knots]!r}: must be finite")


def knot_value(knots: Knots, t_s: float) -> float:
    """The force at ``t_s``: linear between knots, the first one's before them and the last one's after."""
    k = bisect_right(knots, t_s, key=lambda knot: knot[0])
    if k == 0:
        return knots[0][1]
    if k == len(knots):
        return knots[-1][1]
    (t0, f0), (t1, f1) = knots[k - 1], knots[k]
    return f0 + (f1 - f0) * (t_s - t0) / (t1 - t0)


@dataclass(frozen=True, slots=True)
class ForceProgram:
    """A commanded force over time since the loop applied it (module docstring).

    Attributes
    ----------
    knots
        ``(t_s, force_n)``: the force (N, haptic frame ``z``) at ``t_s`` s after the program was applied, from 0 on
        in increasing time; linear between knots, the last one held.
    """

    knots: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        check_knots(self.knots, "ForceProgram", "a program")

    def force_n(self, elapsed_ns: int) -> float:
        """The commanded force ``elapsed_ns`` after the program was applied, N."""
        return knot_value(self.knots, elapsed_ns / 1e9)

    def to_json(self) -> list[list[float]]:
        """As the replay log stores it."""
        return [[t, f] for t, f in self.knots]

    @classmethod
    def from_json(cls, knots: Sequence[Sequence[float]]) -> ForceProgram:
        """From :meth:`to_json`."""
        return cls(tuple((float(t), float(f)) for t, f in knots))
