"""Tool-centre-point (TCP) calibration by pivoting: where the instrument tip is in the flange frame.

The paper (§II): once the instrument is mounted, "it is crucial to precisely
define the Tool Center Point (TCP) at the instrument tip through a
calibration".  The classic pivot calibration: the tip rests in a fixed divot
while the instrument is turned through several orientations; for every
recorded flange pose ``(R_i, p_i)`` (base frame) the tip is at the same point::

    R_i · t + p_i = q          t: tip in the flange frame, q: the divot (pivot) in the base frame

which is linear in ``x = (t, q)``: ``[R_i  −I] x = −p_i``, solved by least
squares over all poses (:func:`identify_tip`).  The residual ``R_i t + p_i − q``
of each pose says how well the tip stayed in the divot.

**Which orientations.**  Eliminating ``q`` leaves ``(R_i − R̄) t = −(p_i − p̄)``:
the component of ``t`` along a flange direction ``v`` is determined only if
the orientations turn ``v`` -- i.e. tilt about axes *across* ``v``.  Turning
the instrument only about its shaft (a pure roll) leaves the tip's distance
along the shaft undetermined; tilting it only about one axis leaves the
component along that axis.  The smallest singular value of the stacked
``R_i − R̄`` (per pose) measures the worst-determined direction;
:func:`identify_tip` converts it to an equivalent tilt range (``spread_deg``)
and refuses a set below :data:`MIN_SPREAD_DEG`, naming the direction and the
axes to tilt about.  With a 0.05 mm robot repeatability and divot seating,
20° of spread gives the tip to about 0.2 mm.

The tip frame T of eq. (2) then has its origin at ``t`` and the flange's
orientation: the robot's TCP is set to ``t`` (on the pendant, or corrected in
software, :class:`pipeline.backends.ur.UrRtdeRobot`), and ᵀ_S R stays the
sensor mount of ``[frames]``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.force.frames import Mat3, Vec3, axis_angle, check_rotation, mat_mul

__all__ = [
    "MAX_RMS_RESIDUAL_M",
    "MIN_PIVOT_POSES",
    "MIN_SPREAD_DEG",
    "PIVOT_POSE_SETS",
    "DegeneratePivotError",
    "PivotPose",
    "TipCalibration",
    "identify_tip",
    "pivot_orientations",
]

#: Fewest orientations a pivot calibration takes.
MIN_PIVOT_POSES = 4
#: Smallest equivalent tilt range about the worst-determined direction, degrees.
MIN_SPREAD_DEG = 20.0
#: Largest RMS residual (tip distance from the fitted pivot) accepted, m: more means the tip moved in the divot.
MAX_RMS_RESIDUAL_M = 0.001
#: Named orientation sets (see :func:`pivot_orientations`).
PIVOT_POSE_SETS = ("recommended", "minimal", "roll only")


class DegeneratePivotError(ValueError):
    """The poses cannot determine the tip; the message says which orientations to add."""

    def __init__(self, message: str, spread_deg: float = math.nan) -> None:
        super().__init__(message)
        self.spread_deg = spread_deg


@dataclass(frozen=True, slots=True)
class PivotPose:
    """One recorded flange pose with the tip in the divot: ``rot_base_flange`` (row-major) and position, m."""

    rot_base_flange: Mat3
    position_m: Vec3
    label: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "rot_base_flange", check_rotation(self.rot_base_flange, f"pose {self.label} rotation"))
        p = tuple(float(v) for v in self.position_m)
        if len(p) != 3 or not all(math.isfinite(v) for v in p):
            raise ValueError(f"pose {self.label} position = {self.position_m!r}: must be 3 finite numbers in metres")
        object.__setattr__(self, "position_m", p)


@dataclass(frozen=True, slots=True)
class TipCalibration:
    """The result of a pivot calibration.

    Attributes
    ----------
    tip_in_flange_m
        The instrument tip in the flange frame, m (the TCP offset to use).
    pivot_base_m
        The divot in the robot base frame, m.
    rms_residual_m
        ``sqrt(mean |R_i t + p_i − q|²)``, m.
    residuals
        Per pose: (label, distance of the tip from the pivot, m).
    spread_deg
        Equivalent tilt range about the worst-determined direction, degrees.
    """

    tip_in_flange_m: Vec3
    pivot_base_m: Vec3
    rms_residual_m: float
    residuals: tuple[tuple[str, float], ...]
    spread_deg: float

    @property
    def n_poses(self) -> int:
        """Orientations the fit used."""
        return len(self.residuals)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe record (inverse of :meth:`from_dict`)."""
        return {
            "tip_in_flange_m": list(self.tip_in_flange_m),
            "pivot_base_m": list(self.pivot_base_m),
            "rms_residual_m": self.rms_residual_m,
            "residuals": [{"label": lab, "residual_m": r} for lab, r in self.residuals],
            "spread_deg": self.spread_deg,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TipCalibration:
        """Rebuild a stored result; :class:`ValueError` naming a missing or bad field."""
        try:
            tip = _vec3(d["tip_in_flange_m"], "tcp.tip_in_flange_m")
            pivot = _vec3(d["pivot_base_m"], "tcp.pivot_base_m")
            res = tuple((str(r["label"]), _finite(r["residual_m"], "tcp.residuals")) for r in d["residuals"])
            return cls(tip, pivot, _finite(d["rms_residual_m"], "tcp.rms_residual_m"), res,
                       _finite(d["spread_deg"], "tcp.spread_deg"))
        except KeyError as exc:
            raise ValueError(f"tcp field {exc.args[0]!r} is missing") from None
        except TypeError as exc:
            raise ValueError(f"tcp record is malformed: {exc}") from None


def _finite(v: Any, name: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f"{name} = {v!r}: must be a finite number")
    return float(v)


def _vec3(v: Any, name: str) -> Vec3:
    if not isinstance(v, (list, tuple)) or len(v) != 3:
        raise ValueError(f"{name} = {v!r}: must be 3 numbers")
    return (_finite(v[0], name), _finite(v[1], name), _finite(v[2], name))


def _direction_words(v: np.ndarray) -> tuple[str, str]:
    """A flange direction in words, and the axes to tilt about to determine it."""
    i = int(np.argmax(np.abs(v)))
    if abs(v[i]) > 0.95:
        name = "xyz"[i]
        others = [a for a in "xyz" if a != name]
        return f"the flange {name} axis", f"the flange {others[0]} or {others[1]} axis"
    return (f"flange direction ({v[0]:+.2f}, {v[1]:+.2f}, {v[2]:+.2f})",
            "axes across that direction")


def identify_tip(poses: Sequence[PivotPose], *, min_spread_deg: float = MIN_SPREAD_DEG,
                 max_rms_residual_m: float = MAX_RMS_RESIDUAL_M) -> TipCalibration:
    """Least-squares pivot calibration (see the module docstring).

    Parameters
    ----------
    poses
        Flange poses with the tip resting in one divot.
    min_spread_deg
        Refuse a set whose worst-determined direction is turned less than this.
    max_rms_residual_m
        Refuse a fit whose RMS residual is larger (the tip slipped in the divot).

    Raises
    ------
    DegeneratePivotError
        Too few poses, or orientations too alike (the message names the direction
        that is not determined and the axes to tilt about).
    ValueError
        The fit is too poor (the message names the worst pose).
    """
    n = len(poses)
    if n < MIN_PIVOT_POSES:
        raise DegeneratePivotError(
            f"{n} orientation{'s' if n != 1 else ''} recorded: a pivot calibration needs at least {MIN_PIVOT_POSES}, "
            f"tilted at least {min_spread_deg:g}° apart in two directions with the tip kept in the divot")
    rots = np.array([np.asarray(p.rot_base_flange, dtype=float).reshape(3, 3) for p in poses])
    pos = np.array([p.position_m for p in poses], dtype=float)
    centred = (rots - rots.mean(axis=0)).reshape(-1, 3)
    _, sv, vt = np.linalg.svd(centred)
    worst = float(sv[-1]) / math.sqrt(n)
    spread = 2.0 * math.degrees(math.asin(min(1.0, worst)))
    if spread < min_spread_deg:
        what, about = _direction_words(vt[-1])
        raise DegeneratePivotError(
            f"the orientations are too alike: the tip's offset along {what} is not determined (the instrument turned "
            f"{spread:.1f}° about axes across it, need at least {min_spread_deg:g}°); add orientations tilted at least "
            f"{min_spread_deg:g}° about {about}, with the tip kept in the divot", spread)
    a = np.zeros((3 * n, 6))
    a[:, :3] = rots.reshape(-1, 3)
    a[:, 3:] = -np.tile(np.eye(3), (n, 1))
    x, *_ = np.linalg.lstsq(a, -pos.reshape(-1), rcond=None)
    tip, pivot = x[:3], x[3:]
    r = np.einsum("nij,j->ni", rots, tip) + pos - pivot
    dist = np.linalg.norm(r, axis=1)
    rms = float(math.sqrt(float(np.mean(dist ** 2))))
    labels = [p.label or f"O{k + 1}" for k, p in enumerate(poses)]
    if not rms <= max_rms_residual_m:
        k = int(np.argmax(dist))
        raise ValueError(
            f"RMS residual {rms * 1e3:.2f} mm is above {max_rms_residual_m * 1e3:g} mm (worst {labels[k]}: "
            f"{dist[k] * 1e3:.2f} mm): the tip moved in the divot or the robot moved while recording; re-seat the tip "
            "and record the orientations again")
    return TipCalibration(
        tuple(float(v) for v in tip), tuple(float(v) for v in pivot), rms,  # type: ignore[arg-type]  # three items each: mypy cannot count a generator
        tuple((lab, float(d)) for lab, d in zip(labels, dist, strict=True)), spread,
    )


def pivot_orientations(name: str, tool_down: Mat3, tilt_deg: float = 30.0) -> list[Mat3]:
    """Flange orientations ``rot_base_flange`` of a named set, around the instrument pointing down.

    ``recommended``: 8 -- tilted ``tilt_deg`` toward ±x, ±y and the four diagonals
    of the base, each with a different roll; ``minimal``: 4 -- tilted toward
    ±x and ±y; ``roll only``: 6 turns about the instrument's own (vertical)
    axis, which leave the tip's distance along the shaft undetermined -- a set
    the calibration refuses (kept so an experimenter can see what a refusal says).
    """
    t = math.radians(tilt_deg)
    if name == "roll only":
        return [mat_mul(axis_angle((0.0, 0.0, 1.0), k * math.pi / 3), tool_down) for k in range(6)]
    if name == "minimal":
        dirs = [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)]
    elif name == "recommended":
        dirs = [(math.cos(k * math.pi / 4), math.sin(k * math.pi / 4)) for k in range(8)]
    else:
        raise ValueError(f"pose set = {name!r}: allowed values are {', '.join(PIVOT_POSE_SETS)}")
    out = []
    for k, (dx, dy) in enumerate(dirs):
        roll = axis_angle((0.0, 0.0, 1.0), k * math.pi / 4)
        # tilt about the horizontal axis across the direction of travel
        out.append(mat_mul(axis_angle((-dy, dx, 0.0), t), mat_mul(tool_down, roll)))
    return out
