"""The frame and sign check: does a push on the tip come out the right way in the base and haptic frames?

The rotations of eqs. (2)–(4) are configuration (``[frames]``) and the
robot's orientation; a sensor mounted 90° off, or a base→haptic rotation with
one sign wrong, makes the pipeline push the participant's hand the wrong way
-- and nothing else notices: the affine payload calibration absorbs any mount
rotation for the *weight*, not for the contact force.  So, with the tip free,
the experimenter pushes it gently along each displayed base axis and the app
checks (:func:`check_axis`):

* the **compensated force in the base frame** (``base_f``: filtered, rotated by
  ᵀ_S R and ᴮ_T R) points along that axis -- the pipeline reports the force the
  environment exerts on the tip, so pushing the tip toward +x reads +x;
* the **force rendered in the haptic frame** (``scaled_f``, the force the
  Touch would render, checked with feedback off) points along ᴴ_B R times that
  axis -- where the participant's hand would be pushed.

Each axis passes when both directions are within :data:`MAX_ANGLE_DEG` (a hand
does not push exactly along an axis; a wrong mount or sign is 90° or 180°
off).  Only samples with at least :data:`MIN_PUSH_N` of force count, so the
rest before and after the push does not dilute the direction.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.force.frames import Mat3, Vec3, check_rotation, mat_vec

__all__ = [
    "AXES",
    "MAX_ANGLE_DEG",
    "MIN_PUSH_N",
    "AxisCheck",
    "FrameCheck",
    "axis_vector",
    "check_axis",
    "direction_name",
]

#: The base axes the experimenter pushes along, in order.
AXES = ("+x", "+y", "+z")
#: Largest angle between the measured and the expected direction that passes, degrees.
MAX_ANGLE_DEG = 30.0
#: Samples with less force than this are rest, not push, N.
MIN_PUSH_N = 0.3
#: The Touch frame's directions as the participant feels them (HDAPI: +x right, +y up, +z toward the user).
_HAPTIC_WORDS = {"+x": "right", "-x": "left", "+y": "up", "-y": "down", "+z": "toward the user",
                 "-z": "away from the user"}


def axis_vector(axis: str) -> Vec3:
    """``"+x"`` → (1, 0, 0), ``"-z"`` → (0, 0, -1)."""
    if len(axis) != 2 or axis[0] not in "+-" or axis[1] not in "xyz":
        raise ValueError(f"axis = {axis!r}: must be one of +x, -x, +y, -y, +z, -z")
    v = [0.0, 0.0, 0.0]
    v["xyz".index(axis[1])] = 1.0 if axis[0] == "+" else -1.0
    return (v[0], v[1], v[2])


def direction_name(v: Sequence[float], haptic: bool = False) -> str:
    """The signed axis a direction is closest to, e.g. ``"-y"`` (``"-y (down)"`` in the haptic frame)."""
    a = np.asarray(v, dtype=float)
    i = int(np.argmax(np.abs(a)))
    name = ("+" if a[i] >= 0 else "-") + "xyz"[i]
    return f"{name} ({_HAPTIC_WORDS[name]})" if haptic else name


def _angle_deg(a: np.ndarray, b: Sequence[float]) -> float:
    c = float(np.dot(a, np.asarray(b, dtype=float)))
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


@dataclass(frozen=True, slots=True)
class AxisCheck:
    """One axis of the check: what was expected, what was measured, and the verdict.

    Attributes
    ----------
    axis
        The base axis pushed along (``"+x"``, ...).
    expected_base, expected_haptic
        Unit vectors the forces should point along (base frame; haptic frame = ᴴ_B R · axis).
    measured_base, measured_haptic
        Mean direction of the samples with at least :data:`MIN_PUSH_N` (zeros if none).
    base_angle_deg, haptic_angle_deg
        Angle between measured and expected, degrees (NaN if there was no push).
    peak_n
        Largest compensated force during the recording, N.
    samples
        Samples that counted as push.
    passed
        Both angles within the limit.
    """

    axis: str
    expected_base: Vec3
    expected_haptic: Vec3
    measured_base: Vec3
    measured_haptic: Vec3
    base_angle_deg: float
    haptic_angle_deg: float
    peak_n: float
    samples: int
    passed: bool

    def describe(self) -> str:
        """One line for the experimenter."""
        if self.samples == 0:
            return (f"{self.axis}  no push felt: the largest force was {self.peak_n:.2f} N (need {MIN_PUSH_N:g} N); "
                    f"push the tip gently along base {self.axis} · FAIL")
        verdict = "PASS" if self.passed else "FAIL"
        base = f"base force {self.base_angle_deg:5.1f}° from {self.axis}"
        if self.base_angle_deg > MAX_ANGLE_DEG:
            base += f", along {direction_name(self.measured_base)}"
        hap = (f"rendered force {self.haptic_angle_deg:5.1f}° from haptic "
               f"{direction_name(self.expected_haptic, haptic=True)}")
        if self.haptic_angle_deg > MAX_ANGLE_DEG:
            hap += f", along {direction_name(self.measured_haptic, haptic=True)}"
        return f"{self.axis}  peak {self.peak_n:.2f} N · {base} · {hap} · {verdict}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe record (NaN angles as None)."""
        def num(v: float) -> float | None:
            return v if math.isfinite(v) else None

        return {
            "axis": self.axis, "expected_base": list(self.expected_base), "expected_haptic": list(self.expected_haptic),
            "measured_base": list(self.measured_base), "measured_haptic": list(self.measured_haptic),
            "base_angle_deg": num(self.base_angle_deg), "haptic_angle_deg": num(self.haptic_angle_deg),
            "peak_n": self.peak_n, "samples": self.samples, "passed": self.passed,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> AxisCheck:
        """Inverse of :meth:`to_dict`."""
        def num(v: Any) -> float:
            return math.nan if v is None else float(v)

        return cls(str(d["axis"]), tuple(d["expected_base"]), tuple(d["expected_haptic"]),
                   tuple(d["measured_base"]), tuple(d["measured_haptic"]),
                   num(d["base_angle_deg"]), num(d["haptic_angle_deg"]), float(d["peak_n"]), int(d["samples"]),
                   bool(d["passed"]))


def check_axis(axis: str, base_f: np.ndarray, scaled_f: np.ndarray, rot_haptic_base: Mat3, *,
               min_push_n: float = MIN_PUSH_N, max_angle_deg: float = MAX_ANGLE_DEG) -> AxisCheck:
    """Judge one push along base ``axis``.

    Parameters
    ----------
    axis
        ``"+x"``, ``"+y"`` or ``"+z"`` (any signed axis).
    base_f
        Compensated, filtered force in the base frame over the recording, N, shape (n, 3).
    scaled_f
        The force to render in the haptic frame over the same samples, N, shape (n, 3).
    rot_haptic_base
        ᴴ_B R of the configuration.
    """
    e = axis_vector(axis)
    eh = mat_vec(rot_haptic_base, e)
    b = np.asarray(base_f, dtype=float).reshape(-1, 3)
    h = np.asarray(scaled_f, dtype=float).reshape(-1, 3)
    ok_rows = np.isfinite(b).all(axis=1) & np.isfinite(h).all(axis=1)
    b, h = b[ok_rows], h[ok_rows]
    mag = np.linalg.norm(b, axis=1)
    peak = float(mag.max()) if len(mag) else 0.0
    push = mag >= min_push_n
    n = int(np.count_nonzero(push))
    zero = (0.0, 0.0, 0.0)
    if n == 0:
        return AxisCheck(axis, e, eh, zero, zero, math.nan, math.nan, peak, 0, False)
    db = b[push].sum(axis=0)
    dh = h[push].sum(axis=0)
    nb, nh = float(np.linalg.norm(db)), float(np.linalg.norm(dh))
    ub = db / nb if nb > 0 else np.zeros(3)
    uh = dh / nh if nh > 0 else np.zeros(3)
    ab = _angle_deg(ub, e) if nb > 0 else math.nan
    ah = _angle_deg(uh, eh) if nh > 0 else math.nan
    passed = ab <= max_angle_deg and ah <= max_angle_deg
    return AxisCheck(axis, e, eh, tuple(float(v) for v in ub), tuple(float(v) for v in uh),  # type: ignore[arg-type]  # three items each: mypy cannot count a generator
                     ab, ah, peak, n, bool(passed))


@dataclass(frozen=True, slots=True)
class FrameCheck:
    """The check over every axis, with the frame configuration it was made with."""

    axes: tuple[AxisCheck, ...]
    rot_tip_sensor: Mat3
    rot_haptic_base: Mat3

    def __post_init__(self) -> None:
        object.__setattr__(self, "rot_tip_sensor", check_rotation(self.rot_tip_sensor, "frames.rot_tip_sensor"))
        object.__setattr__(self, "rot_haptic_base", check_rotation(self.rot_haptic_base, "frames.rot_haptic_base"))

    @property
    def passed(self) -> bool:
        """Every axis was checked and passed."""
        return bool(self.axes) and {a.axis for a in self.axes} >= set(AXES) and all(a.passed for a in self.axes)

    @property
    def failed(self) -> list[AxisCheck]:
        """The axes that failed."""
        return [a for a in self.axes if not a.passed]

    def summary(self) -> str:
        """One line: PASS, or which axes failed and by how much."""
        if self.passed:
            return f"Frames and signs: PASS ({len(self.axes)} of {len(self.axes)} axes)"
        missing = [a for a in AXES if a not in {c.axis for c in self.axes}]
        parts = []
        for a in self.failed:
            if a.samples == 0:
                parts.append(f"{a.axis} (no push felt)")
            else:
                worst = max(v for v in (a.base_angle_deg, a.haptic_angle_deg) if math.isfinite(v))
                parts.append(f"{a.axis} ({worst:.1f}° off)")
        parts += [f"{a} (not checked)" for a in missing]
        head = "Frames and signs: FAIL on " + ", ".join(parts)
        reversed_push = self._pushed_the_wrong_way()
        if reversed_push is not None:
            # a mounting or [frames] error is a rotation: it never turns one axis around while the other two pass
            a = reversed_push
            others = " and ".join(c.axis for c in self.axes if c is not a)
            return (f"{head}: the push was felt along {direction_name(a.measured_base)}, opposite to {a.axis}, while "
                    f"{others} pass; no sensor mounting or [frames] rotation turns one axis around alone, so the tip "
                    f"was pushed the wrong way: push along {a.axis}{' (up)' if a.axis == '+z' else ''} again "
                    "(leave [frames] as it is)")
        return (head + ": the force would push the hand the wrong way; "
                "check the sensor mounting and [frames] rot_tip_sensor / rot_haptic_base, then check again")

    def _pushed_the_wrong_way(self) -> AxisCheck | None:
        """The one axis felt opposite to its push while every other axis passed, else None."""
        failed = self.failed
        if len(failed) != 1 or {a.axis for a in self.axes} != set(AXES) or len(self.axes) != len(AXES):
            return None
        a = failed[0]
        return a if a.samples > 0 and math.isfinite(a.base_angle_deg) and a.base_angle_deg > 150.0 else None

    def matches(self, rot_tip_sensor: Mat3, rot_haptic_base: Mat3) -> bool:
        """The check was made with this frame configuration."""
        return (np.allclose(self.rot_tip_sensor, rot_tip_sensor, atol=1e-9)
                and np.allclose(self.rot_haptic_base, rot_haptic_base, atol=1e-9))

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe record."""
        return {"passed": self.passed, "axes": [a.to_dict() for a in self.axes],
                "rot_tip_sensor": list(self.rot_tip_sensor), "rot_haptic_base": list(self.rot_haptic_base)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> FrameCheck:
        """Inverse of :meth:`to_dict`; :class:`ValueError` naming a missing or bad field."""
        try:
            return cls(tuple(AxisCheck.from_dict(a) for a in d["axes"]), tuple(d["rot_tip_sensor"]),
                       tuple(d["rot_haptic_base"]))
        except KeyError as exc:
            raise ValueError(f"frames field {exc.args[0]!r} is missing") from None
        except (TypeError, ValueError) as exc:
            raise ValueError(f"frames record is malformed: {exc}") from None
