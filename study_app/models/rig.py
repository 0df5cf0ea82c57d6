"""The simulated rig seen from the side: the instrument tip and the deforming tissue surface.

It is the visual cue a participant has with haptics OFF (the camera image of
the paper's Fig. 7); and it is where a person can drive the stylus with the
mouse or the keyboard to rehearse a session without hardware.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from study_app.engine import messages as m
from study_app.models import Emitter

__all__ = ["RigViewModel"]

#: Keyboard step of the manual stylus target, m.
KEY_STEP_M = 0.0005


@dataclass
class RigViewModel:
    """Tip and tissue geometry in millimetres relative to the undeformed surface (x along the tissue, z up)."""

    surface_z_m: float = 0.10
    home_z_m: float = 0.115
    tip_z_mm: float = 15.0
    indentation_mm: float = 0.0
    contact_force_n: float = 0.0
    driver: str = "autopilot"
    manual_y_m: float = 0.0
    dent_width_mm: float = 6.0
    changed: Emitter = field(default_factory=Emitter)
    target_changed: Emitter = field(default_factory=Emitter)

    def apply(self, ev: object) -> None:
        """Geometry from :class:`EngineReady`; driver from :class:`Health`."""
        if isinstance(ev, m.EngineReady):
            self.surface_z_m, self.home_z_m, self.driver = ev.surface_z_m, ev.tip_home_m[2], ev.driver
        elif isinstance(ev, m.Health) and ev.driver != self.driver:
            self.driver = ev.driver
        else:
            return
        self.changed.emit()

    def update(self, tip_z_m: float, true_fz_n: float) -> None:
        """The newest record's tip height and the ground-truth contact force."""
        if not math.isfinite(tip_z_m):
            return
        tip = (tip_z_m - self.surface_z_m) * 1e3
        ind = max(0.0, -tip)
        f = true_fz_n if math.isfinite(true_fz_n) else 0.0
        if (tip, ind, f) != (self.tip_z_mm, self.indentation_mm, self.contact_force_n):
            self.tip_z_mm, self.indentation_mm, self.contact_force_n = tip, ind, f
            self.changed.emit()

    def surface_profile(self, half_width_mm: float = 30.0, n: int = 121) -> tuple[np.ndarray, np.ndarray]:
        """Tissue surface (x, z) in mm: flat, with a smooth dent under the tip as deep as the indentation."""
        x = np.linspace(-half_width_mm, half_width_mm, n)
        w = self.dent_width_mm + 2.0 * self.indentation_mm
        z = -self.indentation_mm * np.exp(-0.5 * (x / (0.5 * w)) ** 2)
        return x, z

    # -- manual driving ---------------------------------------------------------------------------
    def target_for_tip_mm(self, tip_z_mm: float) -> float:
        """The stylus equilibrium (m along the Touch's +y) that brings the tip to ``tip_z_mm`` above the surface."""
        desired_z_m = self.surface_z_m + tip_z_mm * 1e-3
        return desired_z_m - self.home_z_m

    def set_manual_target(self, y_m: float) -> None:
        """Record and announce a new manual target (clamped as the engine clamps it)."""
        y = min(0.005, max(-0.030, float(y_m)))
        self.manual_y_m = y
        self.target_changed.emit(y)

    def step_manual(self, steps: int) -> None:
        """Keyboard: move the target by ``steps`` × 0.5 mm (down is negative)."""
        self.set_manual_target(self.manual_y_m + steps * KEY_STEP_M)
