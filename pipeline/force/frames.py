"""Rotations and the wrench transform between the frames of the rig.

Frames (paper, Sec. IV and Fig. 4):

* ``S`` -- the wrist force/torque sensor,
* ``T`` -- the instrument tip (the UR tool centre point),
* ``B`` -- the robot base,
* ``H`` -- the haptic device (Touch: +x right, +y up, +z toward the user).

Naming convention, fixed here once for the whole code base: ``rot_a_b`` is the
rotation matrix the paper writes :math:`{}^a_b\\mathbf{R}`; it maps a vector
expressed in frame ``b`` into frame ``a`` (``f_a = rot_a_b @ f_b``).  So
``rot_tip_sensor`` is :math:`{}^T_S R` of eq. (TCP), ``rot_base_tip`` is
:math:`{}^B_T R` of eq. (Base) and ``rot_haptic_base`` is :math:`{}^H_B R` of
eq. (Haptic).

Matrices on the real-time path are plain row-major 9-tuples of floats
(:data:`Mat3`): at 1 kHz in CPython a tuple index is several times cheaper
than a NumPy element access.  The public functions accept anything
array-like and convert once.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TypeAlias

Vec3: TypeAlias = tuple[float, float, float]
Mat3: TypeAlias = tuple[float, float, float, float, float, float, float, float, float]

IDENTITY: Mat3 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)

#: Default orthonormality tolerance for configured rotation matrices: far above
#: the rounding of a matrix typed with 15 digits, far below any real error.
ORTHONORMAL_TOL = 1e-6


def as_mat3(m: object) -> Mat3:
    """Convert a 3x3 nested sequence, a flat 9-sequence or an ndarray to :data:`Mat3`."""
    try:
        rows = list(m)  # type: ignore[call-overload]  # m is any sequence or array; a TypeError is caught below
    except TypeError as exc:
        raise TypeError(f"expected a 3x3 matrix, got {m!r}") from exc
    if len(rows) == 9:
        flat = [float(v) for v in rows]
    elif len(rows) == 3:
        flat = []
        for row in rows:
            r = list(row)
            if len(r) != 3:
                raise ValueError(f"expected a 3x3 matrix, got a row of length {len(r)}: {m!r}")
            flat.extend(float(v) for v in r)
    else:
        raise ValueError(f"expected a 3x3 matrix (3 rows or 9 numbers), got {len(rows)} entries: {m!r}")
    return tuple(flat)  # type: ignore[return-value]  # nine items, counted above


def mat_vec(r: Mat3, v: Sequence[float]) -> Vec3:
    """Return ``r @ v`` for a row-major :data:`Mat3` and a 3-vector."""
    x, y, z = v
    return (
        r[0] * x + r[1] * y + r[2] * z,
        r[3] * x + r[4] * y + r[5] * z,
        r[6] * x + r[7] * y + r[8] * z,
    )


def mat_mul(a: Mat3, b: Mat3) -> Mat3:
    """Return the product ``a @ b`` of two row-major 3x3 matrices."""
    return (
        a[0] * b[0] + a[1] * b[3] + a[2] * b[6],
        a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
        a[0] * b[2] + a[1] * b[5] + a[2] * b[8],
        a[3] * b[0] + a[4] * b[3] + a[5] * b[6],
        a[3] * b[1] + a[4] * b[4] + a[5] * b[7],
        a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
        a[6] * b[0] + a[7] * b[3] + a[8] * b[6],
        a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
        a[6] * b[2] + a[7] * b[5] + a[8] * b[8],
    )


def transpose(r: Mat3) -> Mat3:
    """Return the transpose, i.e. the inverse of a rotation (``rot_b_a`` from ``rot_a_b``)."""
    return (r[0], r[3], r[6], r[1], r[4], r[7], r[2], r[5], r[8])


def det3(r: Mat3) -> float:
    """Determinant of a row-major 3x3 matrix."""
    return (
        r[0] * (r[4] * r[8] - r[5] * r[7])
        - r[1] * (r[3] * r[8] - r[5] * r[6])
        + r[2] * (r[3] * r[7] - r[4] * r[6])
    )


def orthonormality_error(r: Mat3) -> float:
    """Largest absolute entry of ``r @ r.T - I`` (0 for an exact rotation)."""
    p = mat_mul(r, transpose(r))
    return max(abs(p[i] - IDENTITY[i]) for i in range(9))


def check_rotation(m: object, name: str, tol: float = ORTHONORMAL_TOL) -> Mat3:
    """Validate a configured rotation matrix and return it as :data:`Mat3`.

    Parameters
    ----------
    m
        The matrix as loaded from a configuration file (3x3 or 9 numbers).
    name
        The configuration field, quoted in the error so the user knows what to fix.
    tol
        Allowed deviation of ``R Rᵀ`` from the identity, entry-wise.

    Raises
    ------
    ValueError
        Naming the field, the offending value and what is allowed, when the
        matrix is not finite, not orthonormal, or a reflection (det = -1).
    """
    try:
        r = as_mat3(m)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: {exc}; a rotation matrix is 3 rows of 3 numbers") from None
    if not all(math.isfinite(v) for v in r):
        raise ValueError(f"{name} = {m!r}: every entry must be a finite number")
    err = orthonormality_error(r)
    if err > tol:
        raise ValueError(
            f"{name} = {m!r} is not a rotation: R·Rᵀ deviates from the identity by {err:.3g} "
            f"(allowed ≤ {tol:g}); rows must be orthonormal unit vectors"
        )
    d = det3(r)
    if d < 0:
        raise ValueError(f"{name} = {m!r} is a reflection (det = {d:.6g}); a rotation has det = +1")
    return r


def rotvec_to_matrix(rx: float, ry: float, rz: float) -> Mat3:
    """Rotation matrix of a rotation vector (axis × angle, rad), as UR reports TCP orientation.

    Rodrigues' formula ``R = I + a [k]x + b [k]x²`` with ``a = sin θ/θ`` and
    ``b = (1 - cos θ)/θ²`` written for the unnormalised vector, with Taylor
    series below θ = 1e-4 so tiny rotations stay accurate to rounding.
    """
    t2 = rx * rx + ry * ry + rz * rz
    if t2 < 1e-8:
        a = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
        b = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
    else:
        t = math.sqrt(t2)
        a = math.sin(t) / t
        # 1 - cos θ = 2 sin²(θ/2) avoids cancellation for small θ
        s = math.sin(0.5 * t)
        b = 2.0 * s * s / t2
    xx, yy, zz = rx * rx, ry * ry, rz * rz
    xy, xz, yz = rx * ry, rx * rz, ry * rz
    return (
        1.0 - b * (yy + zz), b * xy - a * rz, b * xz + a * ry,
        b * xy + a * rz, 1.0 - b * (xx + zz), b * yz - a * rx,
        b * xz - a * ry, b * yz + a * rx, 1.0 - b * (xx + yy),
    )


def matrix_to_rotvec(r: Mat3) -> Vec3:
    """Rotation vector (axis × angle, rad, angle in [0, π]) of a rotation matrix.

    Uses the skew part for angles away from π and the symmetric part near π,
    where the skew part vanishes, so every rotation round-trips.
    """
    tr = r[0] + r[4] + r[8]
    cos_t = max(-1.0, min(1.0, 0.5 * (tr - 1.0)))
    vx, vy, vz = r[7] - r[5], r[2] - r[6], r[3] - r[1]  # 2 sin θ · axis
    sin2 = math.sqrt(vx * vx + vy * vy + vz * vz)  # 2 sin θ
    t = math.atan2(0.5 * sin2, cos_t)
    if t < 1e-6:
        # θ/(2 sin θ) -> 1/2 + θ²/12
        k = 0.5 + t * t / 12.0
        return (vx * k, vy * k, vz * k)
    if t < math.pi - 1e-3:
        k = t / sin2
        return (vx * k, vy * k, vz * k)
    # Near π: R ≈ 2 k kᵀ - I; take the column with the largest diagonal entry.
    d = (r[0], r[4], r[8])
    i = max(range(3), key=lambda j: d[j])
    col = [r[0 * 3 + i] + r[i * 3 + 0], r[1 * 3 + i] + r[i * 3 + 1], r[2 * 3 + i] + r[i * 3 + 2]]
    col[i] = 1.0 + 2.0 * d[i] - tr
    n = math.sqrt(col[0] ** 2 + col[1] ** 2 + col[2] ** 2)
    kx, ky, kz = col[0] / n, col[1] / n, col[2] / n
    # fix the sign with the (small) skew part so the rotation is θ, not -θ
    if kx * vx + ky * vy + kz * vz < 0:
        kx, ky, kz = -kx, -ky, -kz
    return (kx * t, ky * t, kz * t)


def axis_angle(axis: Sequence[float], angle_rad: float) -> Mat3:
    """Rotation of ``angle_rad`` about ``axis`` (any non-zero length)."""
    x, y, z = axis
    n = math.sqrt(x * x + y * y + z * z)
    if not n > 0:
        raise ValueError(f"axis {axis!r} must be a non-zero finite vector")
    return rotvec_to_matrix(x / n * angle_rad, y / n * angle_rad, z / n * angle_rad)


def skew(p: Sequence[float]) -> Mat3:
    """Skew-symmetric matrix ``S(p)`` with ``S(p) v = p × v``."""
    x, y, z = p
    return (0.0, -z, y, z, 0.0, -x, -y, x, 0.0)


def cross(a: Sequence[float], b: Sequence[float]) -> Vec3:
    """Cross product of two 3-vectors (pure Python: ``np.cross`` costs ~13 µs)."""
    return (
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    )


def wrench_transform(
    rot_j_i: Mat3, pos_j_i: Sequence[float], f_i: Sequence[float], tau_i: Sequence[float]
) -> tuple[Vec3, Vec3]:
    """Map a wrench acting at the origin of frame ``i`` to frame ``j`` (paper, eq. 1).

    ``f_j = R f_i`` and ``tau_j = S(P) R f_i + R tau_i``, where ``R = rot_j_i`` and
    ``P = pos_j_i`` is the position of the origin of ``i`` seen from ``j``,
    expressed in ``j``.  Forces are free vectors, so the paper's force path uses
    only the rotation; the lever arm matters for torques.

    Returns
    -------
    (f_j, tau_j)
        Force (N) and torque (N·m) in frame ``j``.
    """
    f_j = mat_vec(rot_j_i, f_i)
    lever = cross(pos_j_i, f_j)
    t = mat_vec(rot_j_i, tau_i)
    return f_j, (lever[0] + t[0], lever[1] + t[1], lever[2] + t[2])


def sensor_to_haptic_chain(rot_tip_sensor: Mat3, rot_base_tip: Mat3, rot_haptic_base: Mat3) -> Mat3:
    """Composite rotation ``rot_haptic_sensor = rot_haptic_base · rot_base_tip · rot_tip_sensor`` (eqs. 2–4)."""
    return mat_mul(rot_haptic_base, mat_mul(rot_base_tip, rot_tip_sensor))
