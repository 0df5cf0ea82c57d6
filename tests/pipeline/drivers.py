"""Stylus drivers shared by the loop and watchdog tests."""

from __future__ import annotations


class PressAndHold:
    """Keep still for ``delay_s`` after the first observation, then hold the equilibrium at ``y_m``.

    The tip starts 15 mm above the tissue: -18 mm presses ~2 mm in (about 1 N
    of tissue force, 0.45 N rendered).
    """

    def __init__(self, y_m: float = -0.018, delay_s: float = 0.05) -> None:
        self.y_m = y_m
        self.delay_s = delay_s
        self._t0: float | None = None

    def equilibrium_y(self, obs) -> float:
        if self._t0 is None:
            self._t0 = obs.t_s
        return self.y_m if obs.t_s - self._t0 >= self.delay_s else 0.0
