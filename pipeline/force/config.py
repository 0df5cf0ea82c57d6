"""The configuration of Algorithm 1 and of its safety stage: what a protocol file, a hardware file or ``--set``
chooses, validated at construction.

Apart from the stages' code (:mod:`pipeline.force.framework`, :mod:`pipeline.force.safety`), which is compiled
(:mod:`pipeline.core.compiled`): reading a study's or a rig's configuration needs no compiler, so a command that
only reads one (``haptic-study --help``, ``check``, ``report``) starts without loading numba.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pipeline.force.frames import IDENTITY, Mat3, check_rotation

__all__ = [
    "DEFAULT_ROT_HAPTIC_BASE",
    "DEFAULT_ROT_TIP_SENSOR",
    "LIMIT_RANGE_N",
    "FrameworkConfig",
    "SafetyConfig",
    "framework_config_from_dict",
    "framework_config_to_dict",
]


@dataclass(frozen=True, slots=True)
class SafetyConfig:
    """Limits of the safety stage.

    Attributes
    ----------
    f_max_n
        Largest rendered magnitude, N (the paper's f_max, 3 N).
    slew_n_per_s
        Largest rate of change of the rendered force, N/s (science.md §5: 20–50).
    ramp_in_s
        Time to fade feedback in after it is enabled or a fault is reset, s.
    fault_ramp_s
        Time to fade to zero on disable or fault, s; must be ≤ 0.05 (a fault
        must bring the force to zero within 50 ms).
    max_dt_s
        For the slew limit and the ramp-in, a tick longer than this (a stalled
        loop) counts as this long, so a late tick cannot jump the force up by
        more than one normal step.  The ramp-down uses the true time.
    """

    f_max_n: float = 3.0
    slew_n_per_s: float = 50.0
    ramp_in_s: float = 0.5
    fault_ramp_s: float = 0.04
    max_dt_s: float = 0.005

    def __post_init__(self) -> None:
        for name, lo, hi, unit in (
            ("f_max_n", 1e-6, 1e3, "N"),
            ("slew_n_per_s", 1e-3, 1e6, "N/s"),
            ("ramp_in_s", 1e-3, 60.0, "s"),
            ("fault_ramp_s", 1e-3, 0.05, "s"),
            ("max_dt_s", 1e-4, 1.0, "s"),
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo <= v <= hi):
                raise ValueError(f"safety.{name} = {v!r}: must be a number from {lo:g} to {hi:g} {unit}")



#: Touch frame (+x right, +y up, +z toward the user) for an experimenter facing
#: the robot along base +y: base x → haptic x, base z (up) → haptic y (up),
#: base −y → haptic z.  Rows are the haptic axes expressed in the base frame.
DEFAULT_ROT_HAPTIC_BASE: Mat3 = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0)
#: Sensor mounted coaxially with the instrument: its axes coincide with the tip's.
DEFAULT_ROT_TIP_SENSOR: Mat3 = IDENTITY


@dataclass(frozen=True, slots=True)
class FrameworkConfig:
    """Parameters of Algorithm 1, validated at construction.

    Attributes
    ----------
    f_max_n, f_scale_n
        Scaling law parameters, N (paper: 3 and 7).
    filter_window
        Moving-average length in samples (group delay (N−1)/2 ms at 1 kHz).
    rot_tip_sensor, rot_haptic_base
        The fixed rotations ᵀ_S R and ᴴ_B R (row-major 9-tuples or 3x3 nested
        sequences); checked for orthonormality.
    safety
        Clamp/slew/ramp limits; its ``f_max_n`` is forced equal to ``f_max_n``.
    """

    f_max_n: float = 3.0
    f_scale_n: float = 7.0
    filter_window: int = 10
    rot_tip_sensor: Mat3 = DEFAULT_ROT_TIP_SENSOR
    rot_haptic_base: Mat3 = DEFAULT_ROT_HAPTIC_BASE
    safety: SafetyConfig = field(default_factory=SafetyConfig)

    def __post_init__(self) -> None:
        for name in ("f_max_n", "f_scale_n"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} = {v!r}: must be a finite number of newtons > 0")
        w = self.filter_window
        if isinstance(w, bool) or not isinstance(w, int) or not 1 <= w <= 1000:
            raise ValueError(f"filter_window = {w!r}: must be a whole number of samples from 1 to 1000")
        object.__setattr__(self, "rot_tip_sensor", check_rotation(self.rot_tip_sensor, "rot_tip_sensor"))
        object.__setattr__(self, "rot_haptic_base", check_rotation(self.rot_haptic_base, "rot_haptic_base"))
        if self.safety.f_max_n != self.f_max_n:
            s = self.safety
            object.__setattr__(
                self,
                "safety",
                SafetyConfig(self.f_max_n, s.slew_n_per_s, s.ramp_in_s, s.fault_ramp_s, s.max_dt_s),
            )



def framework_config_to_dict(config: FrameworkConfig) -> dict[str, Any]:
    """A configuration as plain JSON data (inverse of :func:`framework_config_from_dict`)."""
    return {
        "f_max_n": config.f_max_n, "f_scale_n": config.f_scale_n, "filter_window": config.filter_window,
        "rot_tip_sensor": list(config.rot_tip_sensor), "rot_haptic_base": list(config.rot_haptic_base),
        "safety": {f: getattr(config.safety, f) for f in config.safety.__dataclass_fields__},
    }


def framework_config_from_dict(d: dict[str, Any]) -> FrameworkConfig:
    """The configuration :func:`framework_config_to_dict` wrote (validated like any other)."""
    return FrameworkConfig(
        f_max_n=d["f_max_n"], f_scale_n=d["f_scale_n"], filter_window=d["filter_window"],
        rot_tip_sensor=tuple(d["rot_tip_sensor"]), rot_haptic_base=tuple(d["rot_haptic_base"]),
        safety=SafetyConfig(**d["safety"]),
    )


#: Accepted range of f_max and f_scale, N.  Beyond it the law is meaningless for
#: a haptic device and the bounds on rounding no longer hold (e.g. f_max below
#: the smallest normal double).
LIMIT_RANGE_N = (1e-6, 1e6)
