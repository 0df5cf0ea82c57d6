"""Run-time gravity and bias compensation of the wrist force/torque sensor (science.md §1).

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

This module holds the identified model (:class:`PayloadCalibration`, stored
and reloaded with :meth:`PayloadCalibration.to_dict` /
:meth:`PayloadCalibration.from_dict`) and what the 1 kHz loop evaluates with it:
:meth:`PayloadCalibration.gravity_wrench`, :meth:`PayloadCalibration.compensate`
and :class:`MountedPayload` (the same model evaluated at the robot's tip
orientation for one sensor mount, which the loop uses at every pose update).
All of it is plain float arithmetic on tuples: it runs in the 1 kHz loop,
where a NumPy call costs more than the whole computation.  The offline
identification that produces a :class:`PayloadCalibration` from static poses
(NumPy) is :mod:`pipeline.commissioning.payload_identification`; the online refinement of
its bias is :mod:`pipeline.force.bias_refinement`.

Sign convention: the sensor reports the wrench the tool-side body exerts on it
(science.md §1.1).  A sensor with the opposite convention still compensates
exactly (the fit absorbs the sign), but reports a negative mass.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, ClassVar, TypeAlias

from pipeline.force.frames import IDENTITY, Mat3, Vec3, as_mat3, mat_mul, transpose

__all__ = [
    "GRAVITY_BASE",
    "NO_PAYLOAD",
    "PAYLOAD_MODELS",
    "MountedPayload",
    "PayloadCalibration",
    "PoseResidual",
    "Wrench",
    "finite_tuple",
]

Wrench: TypeAlias = tuple[float, float, float, float, float, float]

#: Gravity in the (level) robot base frame, m/s² (standard gravity, science.md §1.1).
GRAVITY_BASE: Vec3 = (0.0, 0.0, -9.80665)

#: The payload models a calibration can hold (science.md §1.1 and §1.3).
PAYLOAD_MODELS = ("affine", "rigid")
_ZERO3: Vec3 = (0.0, 0.0, 0.0)
_ZERO_MAT: Mat3 = (0.0,) * 9
_DICT_VERSION = 1


def finite_tuple(values: object, n: int, name: str) -> tuple[float, ...]:
    """``values`` as a tuple of ``n`` finite floats.

    Raises
    ------
    ValueError
        ``<name> = <values>: expected <n> finite numbers``.
    """
    try:
        out = tuple(float(v) for v in values)  # type: ignore[attr-defined]  # any iterable; a TypeError is caught below
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {values!r}: expected {n} finite numbers") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} = {values!r}: expected {n} finite numbers")
    return out


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
            object.__setattr__(self, name, finite_tuple(getattr(self, name), 3, f"calibration {name}"))
        object.__setattr__(
            self, "gravity_matrix", finite_tuple(as_mat3(self.gravity_matrix), 9, "calibration gravity_matrix")
        )
        for name in self._SCALARS:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"calibration {name} = {v!r}: must be a finite number")
            object.__setattr__(self, name, float(v))
        if self.model not in PAYLOAD_MODELS:
            raise ValueError(f"calibration model = {self.model!r}: must be one of {PAYLOAD_MODELS}")
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
        :class:`pipeline.force.bias_refinement.RlsBias`, whose input must still contain the bias.

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
        """Copy with new offsets (e.g. from :class:`pipeline.force.bias_refinement.RlsBias` or a re-bias at rest).

        The residual fields still describe the original offline fit.
        """
        fb, tb = tuple(force_bias_n), tuple(torque_bias_nm)
        return replace(self, force_bias_n=fb, torque_bias_nm=tb)  # type: ignore[arg-type]  # three items each: mypy cannot count them

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
            gravity_base=tuple(gravity_base),  # type: ignore[arg-type]  # a Vec3: mypy cannot count tuple()
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

    __slots__ = ("_along_z", "_bias", "_com", "_gravity_base", "_k")

    def __init__(self, calibration: PayloadCalibration, rot_tip_sensor: Mat3) -> None:
        k = mat_mul(calibration.gravity_matrix, transpose(rot_tip_sensor))
        gx, gy, gz = calibration.gravity_base
        self._along_z = gx == 0.0 and gy == 0.0
        self._k: Mat3 = tuple(v * gz for v in k) if self._along_z else k  # type: ignore[assignment]  # nine items: mypy cannot count a generator
        self._gravity_base = calibration.gravity_base
        self._com = calibration.com_m
        self._bias: Wrench = (*calibration.force_bias_n, *calibration.torque_bias_nm)

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
        own offsets (:class:`pipeline.force.framework.HapticFramework`).
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
