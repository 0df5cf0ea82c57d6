"""Gravity and bias compensation of the wrist force/torque sensor (science.md §1).

The sensor ``S`` carries the instrument, so even out of contact it reads the
instrument's weight and its own offset.  With ``g_S`` the gravity vector in the
sensor frame for the current nominal pose (m/s²), the model is

.. math::

    f = A\\,g_S + f_b, \\qquad \\tau = c \\times (A\\,g_S) + \\tau_b

* **rigid** model (10 parameters, science.md §1.1): ``A = m·I``; unknowns
  ``x = [m, m·c, f_b, τ_b]`` solved jointly with the regressor ``H_i`` of §1.1;
* **affine** model (12 + 6 parameters, science.md §1.3): ``A`` is a free 3x3
  matrix, which absorbs the unknown sensor-mount rotation and small gain errors
  (``A ≈ m·R_mountᵀ``).  One degree of unmodelled mount rotation already costs
  about 0.11 N for a 0.65 kg tool (§1.2), more than the ±10 % band of the GENTLE
  target, so the affine model is preferred whenever the poses support it.  The
  torque stage is then a linear LS in ``(c, τ_b)`` given ``f_g = A·g_S``
  (Yu et al.'s two-stage form).

Offline identification (:func:`identify_payload`) uses NumPy.  The real-time
side (:meth:`PayloadCalibration.gravity_wrench`,
:meth:`PayloadCalibration.compensate`, :class:`MountedPayload`, the same
model evaluated at the robot's tip orientation for one sensor mount, which the
loop uses at every pose update, and :class:`RlsBias`) is plain float
arithmetic on tuples: it runs in the 1 kHz loop, where a NumPy call costs more
than the whole computation.

Sign convention: the sensor reports the wrench the tool-side body exerts on it
(science.md §1.1).  A sensor with the opposite convention still compensates
exactly (the fit absorbs the sign), but reports a negative mass.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, ClassVar, TypeAlias

import numpy as np
import numpy.typing as npt

from pipeline.frames import (
    IDENTITY,
    Mat3,
    Vec3,
    as_mat3,
    axis_angle,
    check_rotation,
    mat_mul,
    mat_vec,
    matrix_to_rotvec,
    transpose,
)

__all__ = [
    "GRAVITY_BASE",
    "NO_PAYLOAD",
    "RANK_RTOL",
    "CalibrationPose",
    "DegeneratePoseSetError",
    "MountedPayload",
    "PayloadCalibration",
    "PoseResidual",
    "RlsBias",
    "Wrench",
    "identify_payload",
    "recommended_pose_set",
]

Wrench: TypeAlias = tuple[float, float, float, float, float, float]
_FloatArray: TypeAlias = npt.NDArray[np.float64]

#: Gravity in the (level) robot base frame, m/s² (standard gravity, science.md §1.1).
GRAVITY_BASE: Vec3 = (0.0, 0.0, -9.80665)

#: Singular values of a column-scaled regressor below ``RANK_RTOL·σ_max`` count
#: as zero.  Deliberately far above rounding: a direction excited 1000x less
#: than the best one amplifies the sensor noise 1000x into the parameter, which
#: for a 3 mN sensor means newtons of error, i.e. the parameter is not
#: determined in practice (e.g. a tool-up/tool-down set whose poses differ by a
#: few hundredths of a degree of kinematic error).
RANK_RTOL = 1e-3

_PARAM_NAMES = ("m", "m·c_x", "m·c_y", "m·c_z", "f_b,x", "f_b,y", "f_b,z", "τ_b,x", "τ_b,y", "τ_b,z")
_AXES = ("x", "y", "z")
_ZERO3: Vec3 = (0.0, 0.0, 0.0)
_ZERO_MAT: Mat3 = (0.0,) * 9  # type: ignore[assignment]
_MODELS = ("affine", "rigid")
# A direction is named after a sensor axis when it is within 10° of it.
_AXIS_COS = math.cos(math.radians(10.0))
# RMS component of the unit gravity directions below which a sensor direction
# is reported as "not covered" (≈ 11.5°: less spread than that cannot pin
# down the parameters it excites, see RANK_RTOL).
_COVER_RMS = 0.2
_DICT_VERSION = 1


class DegeneratePoseSetError(ValueError):
    """The calibration poses cannot determine the payload parameters.

    The message says why and which poses to add.

    Attributes
    ----------
    rank
        Numerical rank of the regressor that failed (``None`` if none was built).
    condition_number
        Its condition number with columns scaled to unit norm (``inf`` if singular).
    advice
        The sentence telling the experimenter which poses to add.
    """

    def __init__(
        self, message: str, *, rank: int | None = None, condition_number: float | None = None, advice: str = ""
    ) -> None:
        super().__init__(message)
        self.rank = rank
        self.condition_number = condition_number
        self.advice = advice


def _finite_tuple(values: object, n: int, name: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {values!r}: expected {n} finite numbers") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} = {values!r}: expected {n} finite numbers")
    return out


@dataclass(frozen=True, slots=True)
class CalibrationPose:
    """One static calibration pose: nominal orientation and averaged wrench.

    Attributes
    ----------
    rot_base_sensor
        Nominal sensor orientation in the base frame (maps sensor vectors into
        the base frame), from forward kinematics and the nominal mount.
        Accepts a 3x3 array-like or 9 numbers; stored as :data:`Mat3`.
    wrench
        ``(fx, fy, fz, tx, ty, tz)`` in N and N·m, sensor frame, averaged over
        the samples of the pose (science.md §1.2: 100–500 after a 2 s settle).
    label
        Free text naming the pose in residual reports and error messages.
    """

    rot_base_sensor: Mat3
    wrench: Wrench
    label: str = ""

    def __post_init__(self) -> None:
        where = f"pose {self.label}" if self.label else "pose"
        object.__setattr__(
            self, "rot_base_sensor", check_rotation(self.rot_base_sensor, name=f"{where} rot_base_sensor")
        )
        object.__setattr__(self, "wrench", _finite_tuple(self.wrench, 6, f"{where} wrench"))


@dataclass(frozen=True, slots=True)
class PoseResidual:
    """Fit residual of one calibration pose.

    Attributes
    ----------
    label
        The pose's label (``#i`` by position when it had none).
    force_residual_n
        Norm of measured minus modelled force, N.
    torque_residual_nm
        Norm of measured minus modelled torque, N·m.
    """

    label: str
    force_residual_n: float
    torque_residual_nm: float

    def __post_init__(self) -> None:
        for name in ("force_residual_n", "torque_residual_nm"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"residual {self.label!r}: {name} = {v!r} must be a finite number ≥ 0")
            object.__setattr__(self, name, float(v))


@dataclass(frozen=True, slots=True)
class PayloadCalibration:
    """Identified payload and bias; computes and removes the non-contact wrench.

    Attributes
    ----------
    mass_kg
        Payload mass, kg.  For the affine model the mean singular value of
        ``A`` (signed by ``det A``; negative means the sensor uses the opposite
        sign convention, which the compensation absorbs).
    com_m
        Payload centre of mass in the sensor frame, m.
    force_bias_n, torque_bias_nm
        Sensor offsets ``f_b`` (N) and ``τ_b`` (N·m).
    gravity_matrix
        ``A`` (kg), mapping gravity in S (m/s²) to the weight force the sensor
        reads; ``m·I`` for the rigid model.
    model
        ``"affine"`` or ``"rigid"``.
    rank
        Numerical rank of the 10-column rigid regressor of the poses (10 for
        any accepted pose set; 0 for :meth:`identity`).
    condition_number
        Condition number of the regressor actually solved, with every column
        scaled to unit norm so the value does not depend on units (m/s² vs 1).
        For the affine model the larger of its two stages (force: ``[g_Sᵀ 1]``,
        torque: ``[−[f_g]×  I]``).  science.md §1.2 quotes *unscaled* cond(H),
        which is about 5x larger for the same poses (3 axis-aligned poses:
        2.4 scaled vs 14 unscaled).  0.0 for :meth:`identity`.
    residuals
        Per-pose fit residuals.
    rms_force_residual_n, rms_torque_residual_nm
        ``sqrt(mean(|r_i|²))`` of the per-pose residual norms.
    mount_angle_deg
        Angle of the polar (rotation) factor of ``A/m`` from the identity:
        the sensor-mount rotation the nominal kinematics miss; 0 for rigid.
    gravity_base
        Gravity in the base frame used for the fit, m/s².
    """

    mass_kg: float
    com_m: Vec3
    force_bias_n: Vec3
    torque_bias_nm: Vec3
    gravity_matrix: Mat3
    model: str
    rank: int
    condition_number: float
    residuals: tuple[PoseResidual, ...]
    rms_force_residual_n: float
    rms_torque_residual_nm: float
    mount_angle_deg: float
    gravity_base: Vec3 = GRAVITY_BASE

    _SCALARS: ClassVar[tuple[str, ...]] = (
        "mass_kg",
        "condition_number",
        "rms_force_residual_n",
        "rms_torque_residual_nm",
        "mount_angle_deg",
    )

    def __post_init__(self) -> None:
        for name in ("com_m", "force_bias_n", "torque_bias_nm", "gravity_base"):
            object.__setattr__(self, name, _finite_tuple(getattr(self, name), 3, f"calibration {name}"))
        object.__setattr__(
            self, "gravity_matrix", _finite_tuple(as_mat3(self.gravity_matrix), 9, "calibration gravity_matrix")
        )
        for name in self._SCALARS:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"calibration {name} = {v!r}: must be a finite number")
            object.__setattr__(self, name, float(v))
        if self.model not in _MODELS:
            raise ValueError(f"calibration model = {self.model!r}: must be one of {_MODELS}")
        if isinstance(self.rank, bool) or not isinstance(self.rank, int) or not 0 <= self.rank <= 10:
            raise ValueError(f"calibration rank = {self.rank!r}: must be a whole number from 0 to 10")
        res = tuple(self.residuals)
        if not all(isinstance(r, PoseResidual) for r in res):
            raise ValueError(f"calibration residuals = {self.residuals!r}: must be PoseResidual records")
        object.__setattr__(self, "residuals", res)

    # -- real-time path (pure Python, called at up to 1 kHz) -----------------

    def payload_wrench(self, rot_sensor_base: Mat3) -> Wrench:
        """Weight of the payload as the sensor reads it, without the bias.

        ``(A·g_S, c × A·g_S)`` with ``g_S = rot_sensor_base · gravity_base``.
        Subtract this (not :meth:`gravity_wrench`) from a measurement to feed
        :class:`RlsBias`, whose input must still contain the bias.

        Parameters
        ----------
        rot_sensor_base
            Maps base vectors into the sensor frame (``transpose`` of
            ``rot_base_sensor``); a row-major :data:`Mat3` (no conversion is
            done on this path; use :func:`frames.as_mat3` once, outside the loop).

        Returns
        -------
        tuple of 6 float
            Force (N) and torque (N·m) in the sensor frame.
        """
        # one evaluation of the model: the loop's, with the sensor frame as the "tip" (ᴮ_S R = rot_sensor_baseᵀ)
        return MountedPayload(self, IDENTITY).payload_wrench(transpose(rot_sensor_base))

    def gravity_wrench(self, rot_sensor_base: Mat3) -> Wrench:
        """Non-contact wrench the sensor reads in a pose: payload weight plus bias.

        ``(A·g_S + f_b, c × (A·g_S) + τ_b)``.  Meant to be evaluated at every
        robot pose update (125 Hz) and subtracted at 1 kHz.

        Parameters
        ----------
        rot_sensor_base
            Maps base vectors into the sensor frame, as a row-major :data:`Mat3`.

        Returns
        -------
        tuple of 6 float
            Force (N) and torque (N·m) in the sensor frame.
        """
        w = self.payload_wrench(rot_sensor_base)
        fb = self.force_bias_n
        tb = self.torque_bias_nm
        return (w[0] + fb[0], w[1] + fb[1], w[2] + fb[2], w[3] + tb[0], w[4] + tb[1], w[5] + tb[2])

    def compensate(self, wrench: Sequence[float], rot_sensor_base: Mat3) -> Wrench:
        """External (contact) wrench: measurement minus gravity and bias.

        ``f_ext = f_meas − A·g_S − f_b``, ``τ_ext = τ_meas − c × (A·g_S) − τ_b``.

        Parameters
        ----------
        wrench
            Measured ``(fx, fy, fz, tx, ty, tz)``, N and N·m, sensor frame.
        rot_sensor_base
            Maps base vectors into the sensor frame, as a row-major :data:`Mat3`.

        Returns
        -------
        tuple of 6 float
            The contact wrench in the sensor frame, N and N·m.
        """
        g = self.gravity_wrench(rot_sensor_base)
        return (
            wrench[0] - g[0],
            wrench[1] - g[1],
            wrench[2] - g[2],
            wrench[3] - g[3],
            wrench[4] - g[4],
            wrench[5] - g[5],
        )

    def for_mount(self, rot_tip_sensor: Mat3) -> MountedPayload:
        """This model evaluated from the robot's tip orientation, for a sensor mounted at ``rot_tip_sensor``."""
        return MountedPayload(self, rot_tip_sensor)

    # -- storage and construction -------------------------------------------

    def with_bias(self, force_bias_n: Sequence[float], torque_bias_nm: Sequence[float]) -> PayloadCalibration:
        """Copy with new offsets (e.g. from :class:`RlsBias` or a re-bias at rest).

        The residual fields still describe the original offline fit.
        """
        fb, tb = tuple(force_bias_n), tuple(torque_bias_nm)
        return replace(self, force_bias_n=fb, torque_bias_nm=tb)  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dictionary (lists and finite floats), inverse of :meth:`from_dict`."""
        a = self.gravity_matrix
        return {
            "version": _DICT_VERSION,
            "model": self.model,
            "mass_kg": self.mass_kg,
            "com_m": list(self.com_m),
            "force_bias_n": list(self.force_bias_n),
            "torque_bias_nm": list(self.torque_bias_nm),
            "gravity_matrix": [list(a[0:3]), list(a[3:6]), list(a[6:9])],
            "rank": self.rank,
            "condition_number": self.condition_number,
            "residuals": [
                {"label": r.label, "force_residual_n": r.force_residual_n, "torque_residual_nm": r.torque_residual_nm}
                for r in self.residuals
            ],
            "rms_force_residual_n": self.rms_force_residual_n,
            "rms_torque_residual_nm": self.rms_torque_residual_nm,
            "mount_angle_deg": self.mount_angle_deg,
            "gravity_base": list(self.gravity_base),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> PayloadCalibration:
        """Rebuild a calibration stored with :meth:`to_dict`.

        Raises
        ------
        ValueError
            Naming the missing or invalid field.
        """
        if d.get("version") != _DICT_VERSION:
            raise ValueError(f"calibration version = {d.get('version')!r}: this code reads version {_DICT_VERSION}")
        try:
            residuals = tuple(
                PoseResidual(str(r["label"]), r["force_residual_n"], r["torque_residual_nm"]) for r in d["residuals"]
            )
            return cls(
                mass_kg=d["mass_kg"],
                com_m=d["com_m"],
                force_bias_n=d["force_bias_n"],
                torque_bias_nm=d["torque_bias_nm"],
                gravity_matrix=d["gravity_matrix"],
                model=d["model"],
                rank=d["rank"],
                condition_number=d["condition_number"],
                residuals=residuals,
                rms_force_residual_n=d["rms_force_residual_n"],
                rms_torque_residual_nm=d["rms_torque_residual_nm"],
                mount_angle_deg=d["mount_angle_deg"],
                gravity_base=d["gravity_base"],
            )
        except KeyError as exc:
            raise ValueError(f"calibration field {exc.args[0]!r} is missing") from None
        except TypeError as exc:
            raise ValueError(f"calibration record is malformed: {exc}") from None

    @classmethod
    def identity(cls, gravity_base: Sequence[float] = GRAVITY_BASE) -> PayloadCalibration:
        """No payload, no bias: :meth:`compensate` returns its input unchanged.

        For running before any calibration exists.  ``rank`` and
        ``condition_number`` are 0 because nothing was identified.
        """
        return cls(
            mass_kg=0.0,
            com_m=_ZERO3,
            force_bias_n=_ZERO3,
            torque_bias_nm=_ZERO3,
            gravity_matrix=_ZERO_MAT,
            model="rigid",
            rank=0,
            condition_number=0.0,
            residuals=(),
            rms_force_residual_n=0.0,
            rms_torque_residual_nm=0.0,
            mount_angle_deg=0.0,
            gravity_base=tuple(gravity_base),  # type: ignore[arg-type]
        )


#: Compensation that changes nothing (no calibration yet).
NO_PAYLOAD: PayloadCalibration = PayloadCalibration.identity()


class MountedPayload:
    """The payload model of a calibration as a function of the tip orientation ᴮ_T R.

    The same equations as :meth:`PayloadCalibration.payload_wrench` and
    :meth:`PayloadCalibration.compensate`, factored for the loop, which
    re-evaluates the weight at every robot update (125 Hz) and knows the
    robot's ``rot_base_tip``, not ``rot_sensor_base``.  With
    ``g_S = ᵀ_S Rᵀ · ᴮ_T Rᵀ · g_B``:

    ``A·g_S = K · (ᴮ_T Rᵀ g_B)`` with ``K = A · ᵀ_S Rᵀ`` formed once here.

    With gravity along base z (``g_B = (0, 0, g_z)``, the default)
    ``ᴮ_T Rᵀ g_B`` is ``g_z`` times the last row of ``ᴮ_T R``, and ``g_z`` is
    folded into ``K``: 9 products per pose instead of the 45 of composing
    ``ᴮ_S R`` first.  :meth:`PayloadCalibration.payload_wrench` is this with
    the identity mount; for another mount the association differs, so the two
    agree to rounding (within a few ulps of ``|A|·|g|`` of the exact value).

    Parameters
    ----------
    calibration
        The payload model.
    rot_tip_sensor
        Sensor mount ᵀ_S R, row-major.
    """

    __slots__ = ("_k", "_com", "_gravity_base", "_along_z", "_bias")

    def __init__(self, calibration: PayloadCalibration, rot_tip_sensor: Mat3) -> None:
        k = mat_mul(calibration.gravity_matrix, transpose(rot_tip_sensor))
        gx, gy, gz = calibration.gravity_base
        self._along_z = gx == 0.0 and gy == 0.0
        self._k: Mat3 = tuple(v * gz for v in k) if self._along_z else k  # type: ignore[assignment]
        self._gravity_base = calibration.gravity_base
        self._com = calibration.com_m
        self._bias: Wrench = (*calibration.force_bias_n, *calibration.torque_bias_nm)  # type: ignore[assignment]

    def payload_wrench(self, rot_base_tip: Mat3) -> Wrench:
        """Weight of the payload as the sensor reads it at tip orientation ``rot_base_tip``, without the bias.

        Returns
        -------
        tuple of 6 float
            ``(A·g_S, c × A·g_S)``: force (N) and torque (N·m) in the sensor frame.
        """
        k0, k1, k2, k3, k4, k5, k6, k7, k8 = self._k
        r = rot_base_tip
        if self._along_z:
            x, y, z = r[6], r[7], r[8]
        else:  # ᴮ_T Rᵀ g_B in full
            gx, gy, gz = self._gravity_base
            x = r[0] * gx + r[3] * gy + r[6] * gz
            y = r[1] * gx + r[4] * gy + r[7] * gz
            z = r[2] * gx + r[5] * gy + r[8] * gz
        fx = k0 * x + k1 * y + k2 * z
        fy = k3 * x + k4 * y + k5 * z
        fz = k6 * x + k7 * y + k8 * z
        cx, cy, cz = self._com
        return (fx, fy, fz, cy * fz - cz * fy, cz * fx - cx * fz, cx * fy - cy * fx)

    def compensate(self, wrench: Sequence[float], rot_base_tip: Mat3) -> Wrench:
        """External wrench at tip orientation ``rot_base_tip``: ``f − (A·g_S + f_b)``, ``τ − (c × A·g_S + τ_b)``.

        The calibration's own bias; the loop refines it online and keeps its
        own offsets (:class:`pipeline.framework.HapticFramework`).
        """
        p = self.payload_wrench(rot_base_tip)
        b = self._bias
        return (
            wrench[0] - (p[0] + b[0]),
            wrench[1] - (p[1] + b[1]),
            wrench[2] - (p[2] + b[2]),
            wrench[3] - (p[3] + b[3]),
            wrench[4] - (p[4] + b[4]),
            wrench[5] - (p[5] + b[5]),
        )


# ---------------------------------------------------------------------------
# Offline identification (NumPy)
# ---------------------------------------------------------------------------


def _scaled_svd(m: _FloatArray) -> tuple[_FloatArray, _FloatArray, _FloatArray]:
    """Column norms, singular values and right singular vectors of the column-scaled matrix.

    For a wide matrix the singular values are padded with zeros and ``vt``
    is square, so the whole null space is visible to the caller.
    """
    norms = np.linalg.norm(m, axis=0)
    # A column that is identically zero stays zero (it shows up as a zero
    # singular value, i.e. as a rank deficit) instead of dividing by zero.
    norms = np.where(norms > 0.0, norms, 1.0)
    rows, cols = m.shape
    _, s, vt = np.linalg.svd(m / norms, full_matrices=rows < cols)
    if rows < cols:
        s = np.concatenate([s, np.zeros(cols - rows)])
    return norms, s, vt


def _rank_cond(s: _FloatArray, rtol: float) -> tuple[int, float]:
    rank = int(np.count_nonzero(s > rtol * s[0])) if s.size and s[0] > 0 else 0
    cond = float(s[0] / s[-1]) if s.size and s[-1] > 0 else math.inf
    return rank, cond


def _scaled_lstsq(m: _FloatArray, z: _FloatArray, rtol: float) -> _FloatArray:
    norms = np.linalg.norm(m, axis=0)
    norms = np.where(norms > 0.0, norms, 1.0)
    sol = np.linalg.lstsq(m / norms, z, rcond=rtol)[0]
    return (sol.T / norms).T


def _rigid_regressor(gs: _FloatArray) -> _FloatArray:
    """Stacked 6N x 10 regressor ``H`` of science.md §1.1 for gravity vectors ``gs`` (N x 3)."""
    n = gs.shape[0]
    h = np.zeros((n, 6, 10))
    gx, gy, gz = gs[:, 0], gs[:, 1], gs[:, 2]
    h[:, 0:3, 0] = gs
    h[:, 0:3, 4:7] = np.eye(3)
    # torque = (m c) × g = −[g]× (m c)
    h[:, 3, 2], h[:, 3, 3] = gz, -gy
    h[:, 4, 1], h[:, 4, 3] = -gz, gx
    h[:, 5, 1], h[:, 5, 2] = gy, -gx
    h[:, 3:6, 7:10] = np.eye(3)
    return h.reshape(6 * n, 10)


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


def _undetermined(s: _FloatArray, vt: _FloatArray, rtol: float) -> str:
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


def _coverage_advice(units: _FloatArray) -> tuple[str, str]:
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


def _affine_advice(units: _FloatArray, n: int) -> tuple[str, str]:
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


def _gravity_in_sensor(poses: Sequence[CalibrationPose], gravity_base: Vec3) -> _FloatArray:
    return np.array([mat_vec(transpose(p.rot_base_sensor), gravity_base) for p in poses], dtype=float)


def _polar_rotation(a: _FloatArray) -> tuple[float, _FloatArray]:
    """Signed mean singular value ``m`` and proper rotation ``R`` with ``A ≈ m·R``.

    ``det(U Vᵀ) = sign(det A)``, so ``sign(det A)·U Vᵀ`` is always a rotation:
    a sensor with the opposite sign convention gives a negative mass and a
    small mount angle instead of a reflection.
    """
    u, s, vt = np.linalg.svd(a)
    sign = 1.0 if np.linalg.det(a) >= 0 else -1.0
    return sign * float(s.mean()), sign * (u @ vt)


def identify_payload(
    poses: Sequence[CalibrationPose],
    *,
    model: str = "auto",
    gravity_base: Sequence[float] = GRAVITY_BASE,
    rank_rtol: float = RANK_RTOL,
) -> PayloadCalibration:
    """Identify mass, centre of mass, mount rotation and bias from static poses.

    Least squares on the model of science.md §1.1/§1.3 (see the module
    docstring).  The rigid 10-column regressor is always checked first: its
    rank decides whether the poses determine the payload at all.

    Parameters
    ----------
    poses
        At least 3 poses with at least 3 distinct gravity directions in the
        sensor frame (12+ recommended, tilted ±45–60° about two horizontal
        axes; see :func:`recommended_pose_set`).
    model
        ``"affine"`` (free 3x3 ``A``: absorbs the sensor-mount rotation; needs
        ≥ 6 poses whose gravity directions do not lie in one plane),
        ``"rigid"`` (``A = m·I``) or ``"auto"`` (affine when it is
        identifiable, else rigid).
    gravity_base
        Gravity in the base frame, m/s² (level base: ``(0, 0, -9.80665)``).
    rank_rtol
        Singular values of the column-scaled regressor below
        ``rank_rtol · σ_max`` count as zero (see :data:`RANK_RTOL`).

    Returns
    -------
    PayloadCalibration
        With per-pose residuals, their RMS and the regressor's condition number.

    Raises
    ------
    DegeneratePoseSetError
        When the poses cannot determine the requested model; the message gives
        the rank, the condition number and which poses to add.
    ValueError
        For an unknown ``model`` or a non-finite/zero ``gravity_base``.
    """
    if model not in ("auto", *_MODELS):
        raise ValueError(f"model = {model!r}: must be 'auto', 'affine' or 'rigid'")
    gb: Vec3 = _finite_tuple(gravity_base, 3, "gravity_base")  # type: ignore[assignment]
    g_norm = math.hypot(*gb)
    if not g_norm > 0:
        raise ValueError(f"gravity_base = {gravity_base!r}: must be a non-zero vector")
    if not (0.0 < rank_rtol < 1.0):
        raise ValueError(f"rank_rtol = {rank_rtol!r}: must be between 0 and 1")
    poses = list(poses)
    for p in poses:
        if not isinstance(p, CalibrationPose):
            raise TypeError(f"poses must be CalibrationPose records, got {p!r}")
    n = len(poses)
    if n == 0:
        raise DegeneratePoseSetError(
            "no calibration poses given; record at least 3 (12 or more recommended, see recommended_pose_set)"
        )
    labels = [p.label or f"#{i}" for i, p in enumerate(poses)]
    gs = _gravity_in_sensor(poses, gb)
    units = gs / np.linalg.norm(gs, axis=1, keepdims=True)
    z = np.array([p.wrench for p in poses], dtype=float)

    h = _rigid_regressor(gs)
    _, s_h, vt_h = _scaled_svd(h)
    rank, cond_h = _rank_cond(s_h, rank_rtol)
    if n < 3 or rank < 10:
        situation, advice = _coverage_advice(units)
        head = f"{n} pose{'s are' if n > 1 else ' is'} too few (at least 3 are needed); " if n < 3 else ""
        missing = _undetermined(s_h, vt_h, rank_rtol)
        raise DegeneratePoseSetError(
            f"{head}the calibration poses do not determine the payload: the rigid regressor has rank {rank} "
            f"of 10 (condition number {cond_h:.3g}, columns scaled to unit norm); "
            f"these parameters are not determined: {missing or 'some combination'}. "
            f"Cause: {situation}. To fix: {advice}.",
            rank=rank,
            condition_number=cond_h,
            advice=advice,
        )

    # Affine force regressor [g_Sᵀ 1], shared by the three force axes.
    gmat = np.hstack([gs, np.ones((n, 1))])
    _, s_g, _ = _scaled_svd(gmat)
    rank_g, cond_g = _rank_cond(s_g, rank_rtol)
    affine_ok = n >= 6 and rank_g == 4
    if model == "affine" and not affine_ok:
        if n < 6:
            why = (
                "its 12 force parameters need at least 6 poses (4 whose gravity directions are not "
                f"coplanar, plus redundancy), got {n}"
            )
            situation = "any 3 gravity directions lie in one plane" if n == 3 else f"only {n} poses were given"
            advice = (
                f"add at least {6 - n} more poses at new tilts, out of the plane of the current ones "
                "(see recommended_pose_set)"
            )
        else:
            situation, advice = _affine_advice(units, n)
            why = f"its force regressor [g_Sᵀ 1] has rank {rank_g} of 4 (condition number {cond_g:.3g})"
        raise DegeneratePoseSetError(
            "the affine model (a free 3x3 gravity matrix absorbing the sensor-mount rotation) cannot be "
            f"identified: {why}. Cause: {situation}. To fix: {advice}, or pass model='rigid' "
            f"(the rigid regressor has rank {rank}, condition number {cond_h:.3g}).",
            rank=rank_g,
            condition_number=cond_g,
            advice=advice,
        )
    use_affine = model == "affine" or (model == "auto" and affine_ok)

    if use_affine:
        x = _scaled_lstsq(gmat, z[:, 0:3], rank_rtol)  # 4 x 3: f_iᵀ = g_iᵀ Aᵀ + f_bᵀ
        a = x[0:3].T
        fb = x[3]
        mass, r_polar = _polar_rotation(a)
        mount_deg = math.degrees(math.hypot(*matrix_to_rotvec(as_mat3(r_polar))))
        fg = gs @ a.T
        # Two-stage torque LS (Yu et al. eq. 43–45): τ_i = −[f_g,i]× c + τ_b
        c_rows = np.zeros((n, 3, 6))
        c_rows[:, 0, 1], c_rows[:, 0, 2] = fg[:, 2], -fg[:, 1]
        c_rows[:, 1, 0], c_rows[:, 1, 2] = -fg[:, 2], fg[:, 0]
        c_rows[:, 2, 0], c_rows[:, 2, 1] = fg[:, 1], -fg[:, 0]
        c_rows[:, :, 3:6] = np.eye(3)
        cmat = c_rows.reshape(3 * n, 6)
        _, s_c, _ = _scaled_svd(cmat)
        _, cond_c = _rank_cond(s_c, rank_rtol)
        y = _scaled_lstsq(cmat, z[:, 3:6].reshape(3 * n), rank_rtol)
        com, tb = y[0:3], y[3:6]
        cond = max(cond_g, cond_c)
        gmat_out = as_mat3(a)
        model_out = "affine"
    else:
        x = _scaled_lstsq(h, z.reshape(6 * n), rank_rtol)
        mass = float(x[0])
        # c = (m c)/m; an exactly massless fit has no centre of mass to report
        com = x[1:4] / mass if mass != 0.0 else np.zeros(3)
        fb, tb = x[4:7], x[7:10]
        cond = cond_h
        mount_deg = 0.0
        gmat_out = (mass, 0.0, 0.0, 0.0, mass, 0.0, 0.0, 0.0, mass)
        model_out = "rigid"

    cal = PayloadCalibration(
        mass_kg=mass,
        com_m=tuple(com),  # type: ignore[arg-type]
        force_bias_n=tuple(fb),  # type: ignore[arg-type]
        torque_bias_nm=tuple(tb),  # type: ignore[arg-type]
        gravity_matrix=gmat_out,
        model=model_out,
        rank=rank,
        condition_number=cond,
        residuals=(),
        rms_force_residual_n=0.0,
        rms_torque_residual_nm=0.0,
        mount_angle_deg=mount_deg,
        gravity_base=gb,
    )
    # Residuals through the same code path the loop uses, so they describe
    # exactly what the compensation will leave at these poses.
    residuals = []
    for p, label in zip(poses, labels):
        e = cal.compensate(p.wrench, transpose(p.rot_base_sensor))
        residuals.append(PoseResidual(label, math.hypot(e[0], e[1], e[2]), math.hypot(e[3], e[4], e[5])))
    rms_f = math.sqrt(math.fsum(r.force_residual_n**2 for r in residuals) / n)
    rms_t = math.sqrt(math.fsum(r.torque_residual_nm**2 for r in residuals) / n)
    return replace(cal, residuals=tuple(residuals), rms_force_residual_n=rms_f, rms_torque_residual_nm=rms_t)


def recommended_pose_set(n: int = 24, tilt_deg: float = 60.0, seed: int = 0) -> list[Mat3]:
    """A well-conditioned set of calibration orientations for a tool that points down.

    Follows the rules of thumb of science.md §1.2: the tool is tilted from the
    tool-down reference (``rot_base_sensor = diag(1, -1, -1)``: sensor z along
    base −z, so gravity is along sensor +z) by up to ``tilt_deg`` about
    horizontal axes of every direction, then yawed about the base vertical.

    The gravity directions in the sensor frame follow a golden-angle spiral
    over the spherical cap of half-angle ``tilt_deg`` around sensor +z, with
    equal-area spacing in tilt from 0 (the first pose is exactly tool-down)
    to ``tilt_deg`` (the last).  Tilts differ from pose to pose on purpose:
    directions that share one tilt lie on a circle, i.e. in a plane, where
    the affine (mount-rotation) model is not identifiable.  The yaw about
    the base vertical does not change gravity in S (it varies the arm's
    configuration, exposing kinematic errors as they occur in use).

    Parameters
    ----------
    n
        Number of poses, ≥ 6 (24 recommended).
    tilt_deg
        Largest tilt from tool-down, degrees, in (0, 90].
    seed
        Seeds the spiral's starting azimuth and the yaws; same seed, same set.

    Returns
    -------
    list of Mat3
        ``rot_base_sensor`` for each pose.
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 6:
        raise ValueError(f"n = {n!r}: must be a whole number ≥ 6 (the affine model needs 6 poses)")
    if not (0.0 < tilt_deg <= 90.0):
        raise ValueError(f"tilt_deg = {tilt_deg!r}: must be in (0, 90] degrees")
    rng = np.random.default_rng(seed)
    phase = float(rng.uniform(0.0, 2.0 * math.pi))
    yaws = rng.uniform(-math.pi, math.pi, size=n)
    golden = math.pi * (3.0 - math.sqrt(5.0))
    one_minus_cos = 1.0 - math.cos(math.radians(tilt_deg))
    tool_down: Mat3 = (1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0)
    out: list[Mat3] = []
    for i in range(n):
        cos_t = 1.0 - one_minus_cos * i / (n - 1)
        theta = math.acos(max(-1.0, min(1.0, cos_t)))
        az = phase + golden * i
        d = (math.sin(theta) * math.cos(az), math.sin(theta) * math.sin(az), cos_t)
        # tool_down maps d to (dx, −dy, −dz); tilt that onto −z_B about the
        # horizontal axis (dx, −dy, −dz) × (0, 0, −1) = (dy, dx, 0).
        tilt = axis_angle((d[1], d[0], 0.0), theta) if theta > 0.0 else IDENTITY
        yaw = axis_angle((0.0, 0.0, 1.0), float(yaws[i]))
        out.append(mat_mul(yaw, mat_mul(tilt, tool_down)))
    return out


# ---------------------------------------------------------------------------
# Online bias refinement (pure Python)
# ---------------------------------------------------------------------------


class RlsBias:
    """Recursive least-squares refinement of the 6 sensor offsets (science.md §1.4).

    Mass and centre of mass stay at their offline values; only the bias, the
    part that drifts with temperature (§1.5), adapts.  The bias regressor is
    the identity, so the 6-channel RLS decouples into 6 scalar recursions

    ``e = z − θ;  K = P/(λ + P);  θ ← θ + K e;  P ← min((P − K P)/λ, p_max)``

    All channels share the regressor, the prior ``p0`` and the update instants,
    so their ``P`` are identical; one ``P`` is kept for all six.

    Parameters
    ----------
    initial_force_bias_n, initial_torque_bias_nm
        Starting offsets (N, N·m), normally from the offline calibration.
    forgetting
        λ in (0, 1].  The memory is ``1/(1 − λ)`` updates: at 1 kHz the
        default 0.9995 remembers 2000 samples = 2 s, 0.999 → 1 s, 0.9999 → 10 s;
        λ = 1 never forgets (a running mean).
    p0
        Initial covariance (dimensionless gain scale), 0 < p0 ≤ p_max.  The
        first gain is ``p0/(λ + p0)`` (≈ 0.01 by default: the initial offsets
        are trusted like ~100 samples).
    p_max
        Upper clamp on ``P`` against covariance wind-up.
    gate_force_n
        Contact guard: a sample whose force innovation ``|e_f|`` is not below
        this (N) is ignored, even when the caller allows updates.  ``inf``
        disables the guard.

    Notes
    -----
    With this identity regressor every update excites every parameter, so
    ``P`` cannot wind up while updates happen: it converges monotonically to
    ``1 − λ``, where the filter becomes an exponential average with gain
    ``1 − λ`` (time constant ``1/(1 − λ)`` samples).  ``P`` is frozen while
    updates are not allowed (no information, so no forgetting either): a long
    trial therefore does not inflate the gain of the first sample after it.
    ``p_max`` bounds ``P`` for the remaining cases (``p_max < 1 − λ``).

    The gate compares against the current estimate, so a bias jump larger
    than ``gate_force_n`` is never followed; :attr:`rejected` counts such
    samples, and a growing count at rest means: re-bias offline.
    """

    __slots__ = ("_lam", "_p", "_p0", "_p_max", "_gate2", "_theta", "updates", "rejected")

    def __init__(
        self,
        initial_force_bias_n: Sequence[float],
        initial_torque_bias_nm: Sequence[float],
        forgetting: float = 0.9995,
        p0: float = 1e-2,
        p_max: float = 1.0,
        gate_force_n: float = 0.15,
    ) -> None:
        fb = _finite_tuple(initial_force_bias_n, 3, "initial_force_bias_n")
        tb = _finite_tuple(initial_torque_bias_nm, 3, "initial_torque_bias_nm")
        if not (isinstance(forgetting, (int, float)) and 0.0 < forgetting <= 1.0):
            raise ValueError(f"forgetting = {forgetting!r}: must be in (0, 1] (memory 1/(1 − forgetting) samples)")
        if not (isinstance(p_max, (int, float)) and 0.0 < p_max < math.inf):
            raise ValueError(f"p_max = {p_max!r}: must be a finite number > 0")
        if not (isinstance(p0, (int, float)) and 0.0 < p0 <= p_max):
            raise ValueError(f"p0 = {p0!r}: must be > 0 and ≤ p_max = {p_max!r}")
        if not (isinstance(gate_force_n, (int, float)) and gate_force_n > 0.0):
            raise ValueError(f"gate_force_n = {gate_force_n!r}: must be > 0 N (inf disables the gate)")
        self._lam = float(forgetting)
        self._p0 = float(p0)
        self._p_max = float(p_max)
        self._gate2 = float(gate_force_n) ** 2
        self._theta = [*fb, *tb]
        self._p = self._p0
        #: Number of samples that updated the estimate.
        self.updates = 0
        #: Number of allowed samples refused by the contact gate (or non-finite).
        self.rejected = 0

    def reset(self, force_bias_n: Sequence[float], torque_bias_nm: Sequence[float]) -> None:
        """Restart from new offsets (e.g. after a re-bias at rest) with ``P = p0``."""
        fb = _finite_tuple(force_bias_n, 3, "force_bias_n")
        self._theta = [*fb, *_finite_tuple(torque_bias_nm, 3, "torque_bias_nm")]
        self._p = self._p0
        self.updates = 0
        self.rejected = 0

    def update(self, wrench_minus_gravity: Sequence[float], allowed: bool) -> bool:
        """Feed one sample; return whether it updated the estimate.

        Parameters
        ----------
        wrench_minus_gravity
            Measured wrench minus the payload weight only
            (:meth:`PayloadCalibration.payload_wrench`), N and N·m: out of
            contact it equals bias + noise.
        allowed
            True when the caller knows the tool is out of contact (not in a
            trial, not near tissue, low acceleration).  Contact absorbed into
            the bias would cancel exactly the force the user should feel.

        Returns
        -------
        bool
            True if the sample was used.
        """
        if not allowed:
            return False
        th = self._theta
        fx, fy, fz, tx, ty, tz = wrench_minus_gravity
        ex, ey, ez = fx - th[0], fy - th[1], fz - th[2]
        etx, ety, etz = tx - th[3], ty - th[4], tz - th[5]
        # NaN fails both comparisons, so a corrupt sample is refused too
        if not (ex * ex + ey * ey + ez * ez < self._gate2 and abs(etx) + abs(ety) + abs(etz) < math.inf):
            self.rejected += 1
            return False
        p = self._p
        k = p / (self._lam + p)
        th[0] += k * ex
        th[1] += k * ey
        th[2] += k * ez
        th[3] += k * etx
        th[4] += k * ety
        th[5] += k * etz
        p = (p - k * p) / self._lam
        self._p = p if p < self._p_max else self._p_max
        self.updates += 1
        return True

    @property
    def force_bias_n(self) -> Vec3:
        """Current force offset estimate, N."""
        th = self._theta
        return (th[0], th[1], th[2])

    @property
    def torque_bias_nm(self) -> Vec3:
        """Current torque offset estimate, N·m."""
        th = self._theta
        return (th[3], th[4], th[5])

    @property
    def covariance(self) -> float:
        """Current ``P`` (the same for all six channels)."""
        return self._p

    def state(self) -> dict[str, Any]:
        """Everything that determines the next update, JSON-safe and exact (see :meth:`from_state`)."""
        return {"forgetting": self._lam, "p0": self._p0, "p_max": self._p_max, "gate2": self._gate2,
                "theta": list(self._theta), "p": self._p, "updates": self.updates, "rejected": self.rejected}

    @classmethod
    def from_state(cls, d: Mapping[str, Any]) -> RlsBias:
        """The estimator exactly as :meth:`state` saw it."""
        th = [float(v) for v in d["theta"]]
        rls = cls(th[:3], th[3:], forgetting=float(d["forgetting"]), p0=float(d["p0"]), p_max=float(d["p_max"]))
        rls._gate2 = float(d["gate2"])
        rls._p = float(d["p"])
        rls.updates, rls.rejected = int(d["updates"]), int(d["rejected"])
        return rls
