"""Offline identification of the instrument's payload and the sensor's bias from static poses (science.md §1.1–§1.3).

:func:`identify_payload` fits the model of :mod:`pipeline.force.payload_compensator`
(rigid: ``A = m·I``, 10 parameters; affine: a free 3x3 ``A`` absorbing the
sensor-mount rotation, 12 + 6 parameters) to averaged wrenches recorded at
known orientations (:class:`CalibrationPose`), and says which poses to add
when they cannot determine it (:class:`DegeneratePoseSetError`).
:func:`recommended_pose_set` proposes a well-conditioned set.

This runs once, before a session, and uses NumPy; the run-time side that
evaluates the result at 1 kHz is plain float arithmetic
(:mod:`pipeline.force.payload_compensator`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple, TypeAlias

import numpy as np
import numpy.typing as npt

from pipeline.commissioning.pose_advice import affine_advice, coverage_advice, undetermined_parameters
from pipeline.force.frames import (
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
from pipeline.force.payload_compensator import (
    GRAVITY_BASE,
    PAYLOAD_MODELS,
    PayloadCalibration,
    PoseResidual,
    Wrench,
    finite_tuple,
)

__all__ = [
    "RANK_RTOL",
    "CalibrationPose",
    "DegeneratePoseSetError",
    "identify_payload",
    "recommended_pose_set",
]

_FloatArray: TypeAlias = npt.NDArray[np.float64]

#: as zero.  Deliberately far above rounding: a direction excited 1000x less
#: than the best one amplifies the sensor noise 1000x into the parameter, which
#: for a 3 mN sensor means newtons of error, i.e. the parameter is not
#: determined in practice (e.g. a tool-up/tool-down set whose poses differ by a
#: few hundredths of a degree of kinematic error).
RANK_RTOL = 1e-3



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
        object.__setattr__(self, "wrench", finite_tuple(self.wrench, 6, f"{where} wrench"))



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

class _Fit(NamedTuple):
    """One model's least-squares solution, before its residuals are known."""

    mass_kg: float
    com_m: _FloatArray
    force_bias_n: _FloatArray
    torque_bias_nm: _FloatArray
    gravity_matrix: Mat3
    model: str
    condition_number: float
    mount_angle_deg: float


def _checked_inputs(
    poses: Sequence[CalibrationPose], model: str, gravity_base: Sequence[float], rank_rtol: float
) -> tuple[list[CalibrationPose], Vec3]:
    """The poses as a non-empty list and gravity as a :data:`Vec3`, or the error naming what is wrong."""
    if model not in ("auto", *PAYLOAD_MODELS):
        raise ValueError(f"model = {model!r}: must be 'auto', 'affine' or 'rigid'")
    gb: Vec3 = finite_tuple(gravity_base, 3, "gravity_base")  # type: ignore[assignment]  # finite_tuple checked it has 3 items
    g_norm = math.hypot(*gb)
    if not g_norm > 0:
        raise ValueError(f"gravity_base = {gravity_base!r}: must be a non-zero vector")
    if not (0.0 < rank_rtol < 1.0):
        raise ValueError(f"rank_rtol = {rank_rtol!r}: must be between 0 and 1")
    poses = list(poses)
    for p in poses:
        if not isinstance(p, CalibrationPose):
            raise TypeError(f"poses must be CalibrationPose records, got {p!r}")
    if not poses:
        raise DegeneratePoseSetError(
            "no calibration poses given; record at least 3 (12 or more recommended, see recommended_pose_set)"
        )
    return poses, gb


def _check_rigid_rank(h: _FloatArray, units: _FloatArray, rank_rtol: float) -> tuple[int, float]:
    """Rank and condition number of the rigid regressor ``h``; too few poses or a rank deficit raise.

    The rigid regressor's rank decides whether the poses determine the payload at all, whatever the model.
    """
    n = units.shape[0]
    _, s_h, vt_h = _scaled_svd(h)
    rank, cond_h = _rank_cond(s_h, rank_rtol)
    if n < 3 or rank < 10:
        situation, advice = coverage_advice(units)
        head = f"{n} pose{'s are' if n > 1 else ' is'} too few (at least 3 are needed); " if n < 3 else ""
        missing = undetermined_parameters(s_h, vt_h, rank_rtol)
        raise DegeneratePoseSetError(
            f"{head}the calibration poses do not determine the payload: the rigid regressor has rank {rank} "
            f"of 10 (condition number {cond_h:.3g}, columns scaled to unit norm); "
            f"these parameters are not determined: {missing or 'some combination'}. "
            f"Cause: {situation}. To fix: {advice}.",
            rank=rank,
            condition_number=cond_h,
            advice=advice,
        )
    return rank, cond_h


def _affine_identifiable(
    gmat: _FloatArray, units: _FloatArray, model: str, rank: int, cond_h: float, rank_rtol: float
) -> tuple[bool, float]:
    """Whether the affine force regressor ``gmat`` (``[g_Sᵀ 1]``) is identifiable, and its condition number.

    Raises when ``model`` is ``"affine"`` and it is not (``rank``, ``cond_h``: the rigid regressor's, for
    the message).
    """
    n = units.shape[0]
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
            situation, advice = affine_advice(units, n)
            why = f"its force regressor [g_Sᵀ 1] has rank {rank_g} of 4 (condition number {cond_g:.3g})"
        raise DegeneratePoseSetError(
            "the affine model (a free 3x3 gravity matrix absorbing the sensor-mount rotation) cannot be "
            f"identified: {why}. Cause: {situation}. To fix: {advice}, or pass model='rigid' "
            f"(the rigid regressor has rank {rank}, condition number {cond_h:.3g}).",
            rank=rank_g,
            condition_number=cond_g,
            advice=advice,
        )
    return affine_ok, cond_g


def _fit_affine(gs: _FloatArray, gmat: _FloatArray, z: _FloatArray, cond_g: float, rank_rtol: float) -> _Fit:
    """The affine model (science.md §1.3): force LS for ``A`` and ``f_b``, then torque LS for ``c`` and ``τ_b``."""
    n = gs.shape[0]
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
    return _Fit(mass, com, fb, tb, as_mat3(a), "affine", max(cond_g, cond_c), mount_deg)


def _fit_rigid(h: _FloatArray, z: _FloatArray, cond_h: float, rank_rtol: float) -> _Fit:
    """The rigid model (science.md §1.1): one LS for ``[m, m·c, f_b, τ_b]``."""
    n = z.shape[0]
    x = _scaled_lstsq(h, z.reshape(6 * n), rank_rtol)
    mass = float(x[0])
    # c = (m c)/m; an exactly massless fit has no centre of mass to report
    com = x[1:4] / mass if mass != 0.0 else np.zeros(3)
    fb, tb = x[4:7], x[7:10]
    return _Fit(mass, com, fb, tb, (mass, 0.0, 0.0, 0.0, mass, 0.0, 0.0, 0.0, mass), "rigid", cond_h, 0.0)


def _with_residuals(fit: _Fit, rank: int, gb: Vec3, poses: Sequence[CalibrationPose]) -> PayloadCalibration:
    """The calibration of ``fit`` with its per-pose residuals and their RMS."""
    cal = PayloadCalibration(
        mass_kg=fit.mass_kg,
        com_m=tuple(fit.com_m),
        force_bias_n=tuple(fit.force_bias_n),
        torque_bias_nm=tuple(fit.torque_bias_nm),
        gravity_matrix=fit.gravity_matrix,
        model=fit.model,
        rank=rank,
        condition_number=fit.condition_number,
        residuals=(),
        rms_force_residual_n=0.0,
        rms_torque_residual_nm=0.0,
        mount_angle_deg=fit.mount_angle_deg,
        gravity_base=gb,
    )
    # Residuals through the same code path the loop uses, so they describe
    # exactly what the compensation will leave at these poses.
    n = len(poses)
    residuals = []
    for i, p in enumerate(poses):
        e = cal.compensate(p.wrench, transpose(p.rot_base_sensor))
        label = p.label or f"#{i}"
        residuals.append(PoseResidual(label, math.hypot(e[0], e[1], e[2]), math.hypot(e[3], e[4], e[5])))
    rms_f = math.sqrt(math.fsum(r.force_residual_n**2 for r in residuals) / n)
    rms_t = math.sqrt(math.fsum(r.torque_residual_nm**2 for r in residuals) / n)
    return replace(cal, residuals=tuple(residuals), rms_force_residual_n=rms_f, rms_torque_residual_nm=rms_t)


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
    poses, gb = _checked_inputs(poses, model, gravity_base, rank_rtol)
    n = len(poses)
    gs = _gravity_in_sensor(poses, gb)
    units = gs / np.linalg.norm(gs, axis=1, keepdims=True)
    z = np.array([p.wrench for p in poses], dtype=float)
    h = _rigid_regressor(gs)
    rank, cond_h = _check_rigid_rank(h, units, rank_rtol)
    # Affine force regressor [g_Sᵀ 1], shared by the three force axes.
    gmat = np.hstack([gs, np.ones((n, 1))])
    affine_ok, cond_g = _affine_identifiable(gmat, units, model, rank, cond_h, rank_rtol)
    if model == "affine" or (model == "auto" and affine_ok):
        fit = _fit_affine(gs, gmat, z, cond_g, rank_rtol)
    else:
        fit = _fit_rigid(h, z, cond_h, rank_rtol)
    return _with_residuals(fit, rank, gb, poses)


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
