"""What to tell the experimenter when calibration poses cannot determine the payload (science.md §1.2).

:func:`pipeline.commissioning.payload_identification.identify_payload` refuses a pose set
whose regressor is rank-deficient; these functions turn the singular vectors
of the gravity directions into the sentence of its error: which parameters
are not determined, what the poses cover, and which poses to add.  Directions
within 10° of a sensor axis are named after it.
"""

from __future__ import annotations

import math
from typing import TypeAlias

import numpy as np
import numpy.typing as npt

__all__ = ["affine_advice", "coverage_advice", "undetermined_parameters"]

_FloatArray: TypeAlias = npt.NDArray[np.float64]

_PARAM_NAMES = ("m", "m·c_x", "m·c_y", "m·c_z", "f_b,x", "f_b,y", "f_b,z", "τ_b,x", "τ_b,y", "τ_b,z")
_AXES = ("x", "y", "z")
# A direction is named after a sensor axis when it is within 10° of it.
_AXIS_COS = math.cos(math.radians(10.0))
# RMS component of the unit gravity directions below which a sensor direction
# is reported as "not covered" (≈ 11.5°: less spread than that cannot pin
# down the parameters it excites, see RANK_RTOL).
_COVER_RMS = 0.2


def _name_dir(v: _FloatArray, signed: bool = True) -> str:
    i = int(np.argmax(np.abs(v)))
    if abs(v[i]) >= _AXIS_COS:
        sign = ("+" if v[i] > 0 else "-") if signed else ""
        return f"sensor {sign}{_AXES[i]}"
    return "sensor direction ({:.2f}, {:.2f}, {:.2f})".format(*v)


def _axis_index(v: _FloatArray) -> int | None:
    i = int(np.argmax(np.abs(v)))
    return i if abs(v[i]) >= _AXIS_COS else None


def _complement(d: _FloatArray) -> tuple[_FloatArray, _FloatArray]:
    """Two unit directions perpendicular to ``d``: sensor axes if ``d`` is near one."""
    i = _axis_index(d)
    if i is not None:
        others = [j for j in range(3) if j != i]
        return np.eye(3)[others[0]], np.eye(3)[others[1]]
    k = int(np.argmin(np.abs(d)))
    w1 = np.cross(d, np.eye(3)[k])
    w1 /= np.linalg.norm(w1)
    return w1, np.cross(d, w1)


def _pair_words(a: _FloatArray, b: _FloatArray) -> tuple[str, str]:
    """("sensor x and y axes", "sensor x and y") or the generic direction form."""
    ia, ib = _axis_index(a), _axis_index(b)
    if ia is not None and ib is not None:
        x, y = sorted((_AXES[ia], _AXES[ib]))
        return f"sensor {x} and {y} axes", f"sensor {x} and {y}"
    na, nb = _name_dir(a, signed=False), _name_dir(b, signed=False)
    return f"axes along {na} and {nb}", f"{na} and {nb}"


def undetermined_parameters(s: _FloatArray, vt: _FloatArray, rtol: float) -> str:
    """Name the parameters with a component in the numerical null space.

    A multi-dimensional null space has no preferred basis, so rather than
    its (arbitrary) singular vectors, report each parameter whose unit vector
    projects onto it noticeably: those cannot be told apart from others.
    """
    null = vt[s <= rtol * s[0]]
    weight = np.sum(null * null, axis=0)
    return ", ".join(_PARAM_NAMES[k] for k in range(len(_PARAM_NAMES)) if weight[k] >= 0.1)


def _all_poses(n: int) -> str:
    return "the only pose has" if n == 1 else "both poses have" if n == 2 else f"all {n} poses have"


def coverage_advice(units: _FloatArray) -> tuple[str, str]:
    """What the gravity directions cover and which poses to add, for a rigid rank deficit.

    Returns ``(situation, advice)``.  ``units`` are the N x 3 unit gravity
    directions in S.  The rigid model needs three distinct directions (two
    non-parallel differences, science.md §1.2); a rank deficit therefore means
    the directions cluster around one axis (or its two ends) or around two
    directions.  Which case it is follows from how much of the unit vectors
    lies along each principal direction.
    """
    n = units.shape[0]
    _, s, vt = np.linalg.svd(units, full_matrices=True)  # vt is 3x3 even for N < 3
    rms = np.zeros(3)
    rms[: s.size] = s / math.sqrt(n)
    weak = [j for j in (1, 2) if rms[j] < _COVER_RMS]
    if not weak:
        # well spread yet rank-deficient: only reachable with a very loose rank_rtol
        return (
            f"the gravity directions of the {n} poses do not separate all parameters",
            "add poses tilted 45–60° from the current ones in several directions (see recommended_pose_set)",
        )
    if len(weak) == 1:
        normal = vt[2]
        a, b = _complement(normal)
        ia, ib = _axis_index(a), _axis_index(b)
        plane = (
            "the sensor {}–{} plane".format(*sorted((_AXES[ia], _AXES[ib])))
            if ia is not None and ib is not None
            else f"the plane perpendicular to {_name_dir(normal, signed=False)}"
        )
        tilt_axes, _ = _pair_words(a, b)
        situation = (
            f"the {n} poses have gravity in only 2 distinct directions, spanning {plane}, "
            f"so nothing excites the payload along {_name_dir(normal, signed=False)}"
        )
        advice = (
            f"add poses (at least 1, better 4) that tilt the tool at least 45° about the {tilt_axes} "
            f"(whichever is not along gravity in that pose) so gravity has a component along "
            f"{_name_dir(normal, signed=False)}, e.g. ±60° from the current poses"
        )
        return situation, advice
    d = vt[0]
    proj = units @ d
    if np.all(proj < 0):
        d, proj = -d, -proj
    both = bool(np.any(proj < 0))
    i = _axis_index(d)
    if i is not None:
        axis = f"sensor {'±' if both else ('+' if d[i] > 0 else '-')}{_AXES[i]} axis"
    else:
        axis = "sensor direction {}({:.2f}, {:.2f}, {:.2f})".format("±" if both else "", *d)
    tool = ""
    if i == 2:
        # tool-down (rot_base_sensor = diag(1, -1, -1)) puts gravity along +z_S
        tool = " (tool up / tool down)" if both else (" (tool down)" if d[2] > 0 else " (tool up)")
    elif i is not None:
        tool = " (tool horizontal)"
    w1, w2 = _complement(d)
    tilt_axes, components = _pair_words(w1, w2)
    situation = f"{_all_poses(n)} gravity along the {axis}{tool}"
    advice = (
        f"add poses that tilt the tool at least 45° about the {tilt_axes} so gravity has a "
        f"component along {components} (e.g. 4 poses tilted ±60°, two about each axis)"
    )
    return situation, advice


def affine_advice(units: _FloatArray, n: int) -> tuple[str, str]:
    """Why ``[g_Sᵀ 1]`` is rank-deficient (gravity directions coplanar) and what to add."""
    centre = units.mean(axis=0)
    _, _, vt = np.linalg.svd(units - centre, full_matrices=False)
    normal = vt[-1]
    h = float(centre @ normal)
    if h < 0:
        normal, h = -normal, -h
    if h < 0.1:
        name = _name_dir(normal, signed=False)
        w1, w2 = _complement(normal)
        tilt_axes, _ = _pair_words(w1, w2)
        situation = (
            f"the gravity directions of the {n} poses lie on one great circle, perpendicular to {name} "
            f"(the poses differ only by rotations about the {name} axis)"
        )
        advice = (
            f"add poses tilted at least 45° out of that plane, about the {tilt_axes} "
            f"(whichever is not along gravity), so gravity has a component along {name}"
        )
    else:
        name = _name_dir(normal)
        tilts = np.degrees(np.arccos(np.clip(units @ normal, -1.0, 1.0)))
        if np.ptp(tilts) >= 2.0:
            # a shallow cap: curved, but too little to tell from a plane
            situation = (
                f"the gravity directions of the {n} poses all stay within {tilts.max():.0f}° of {name}, "
                "too close to one plane to separate the mount rotation from the bias"
            )
            advice = f"add poses tilted 45–60° from {name} in several directions (see recommended_pose_set)"
            return situation, advice
        half = math.degrees(math.acos(min(1.0, h)))
        situation = (
            f"the gravity directions of the {n} poses lie on one cone of half-angle {half:.0f}° around {name} "
            f"(same tilt, different yaw)"
        )
        advice = (
            f"add poses at other tilts from {name}: e.g. one with gravity along {name} (untilted) "
            f"and some tilted about {max(half / 2.0, 30.0):.0f}°"
        )
    return situation, advice
