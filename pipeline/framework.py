"""Algorithm 1 of the paper: the real-time haptic feedback framework, one tick at a time.

Per F/T sample (1 kHz)::

    f_ext,S  = f_meas − (A·g_S + f_b)             compensation   (science.md §1)
    f̄_S      = MovingAverage(f_ext,S)             after compensation (paper §IV)
    f_T      = rot_tip_sensor · f̄_S               eq. (TCP)
    f_B      = rot_base_tip   · f_T               eq. (Base)
    f_H      = rot_haptic_base · f_B              eq. (Haptic)
    f_scaled = f_max · tanh(|f_H|/f_scale) f_H/|f_H|   eq. (H_scaled)
    f_render = safety(f_scaled)                   clamp, slew, ramps (science.md §5)

The gravity term depends on the robot pose, which changes at 125 Hz (CB3), so
it is recomputed in :meth:`HapticFramework.set_pose`, not per sample.  The
per-sample path is pure float arithmetic with every stage's state held
locally: it is the hot loop of the product (≤ 2 µs per tick, see
``haptic-study bench pipeline``).  The stage modules own the equations;
this class only sequences them, except the three rotations, which are
``frames.mat_vec`` written out in place because a call per rotation would be
a third of the budget.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from pipeline.compensation import NO_PAYLOAD, PayloadCalibration, RlsBias
from pipeline.filters import MovingAverage3
from pipeline.frames import IDENTITY, Mat3, check_rotation, mat_mul, transpose
from pipeline.safety import SafetyConfig, SafetyGovernor
from pipeline.scaling import scale_components

__all__ = ["FrameworkConfig", "HapticFramework", "STEP_FIELDS", "DEFAULT_ROT_HAPTIC_BASE", "DEFAULT_ROT_TIP_SENSOR"]

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


#: Names of the values :meth:`HapticFramework.step` returns, in order.
STEP_FIELDS: tuple[str, ...] = (
    "comp_fx", "comp_fy", "comp_fz", "comp_tx", "comp_ty", "comp_tz",
    "filt_fx", "filt_fy", "filt_fz",
    "tip_fx", "tip_fy", "tip_fz",
    "base_fx", "base_fy", "base_fz",
    "haptic_fx", "haptic_fy", "haptic_fz",
    "scaled_fx", "scaled_fy", "scaled_fz",
    "render_fx", "render_fy", "render_fz",
    "force_n",
)


class HapticFramework:
    """The per-tick force path from a raw wrench to the force sent to the device.

    Parameters
    ----------
    config
        Algorithm parameters.
    calibration
        Payload/bias model from :func:`pipeline.compensation.identify_payload`
        (default: none, compensation is a no-op).
    device_peak_n
        Peak force of the haptic device, N (safety clamp).
    rls
        Optional online bias refinement (science.md §1.4).
    """

    __slots__ = (
        "config", "calibration", "filter", "safety", "rls",
        "_off", "_rts", "_rbt", "_rhb", "_fmax", "_fscale", "_rot_base_tip",
    )

    def __init__(
        self,
        config: FrameworkConfig,
        calibration: PayloadCalibration = NO_PAYLOAD,
        device_peak_n: float = 3.3,
        rls: RlsBias | None = None,
    ) -> None:
        self.config = config
        self.calibration = calibration
        self.filter = MovingAverage3(config.filter_window)
        self.safety = SafetyGovernor(config.safety, device_peak_n)
        self.rls = rls
        self._fmax = float(config.f_max_n)
        self._fscale = float(config.f_scale_n)
        self._rts = config.rot_tip_sensor
        self._rhb = config.rot_haptic_base
        self._rot_base_tip: Mat3 = IDENTITY
        self._rbt: Mat3 = IDENTITY
        self._off: tuple[float, float, float, float, float, float] = (0.0,) * 6  # type: ignore[assignment]
        self.set_pose(IDENTITY)

    def set_pose(self, rot_base_tip: Mat3) -> None:
        """Take a new robot orientation ᴮ_T R (at each robot update, 125 Hz on a CB3).

        Recomputes the gravity + bias wrench the sensor reads in this pose.
        """
        self._rot_base_tip = rot_base_tip
        self._rbt = rot_base_tip
        rot_sensor_base = transpose(mat_mul(rot_base_tip, self._rts))
        self._off = self.calibration.gravity_wrench(rot_sensor_base)

    def set_calibration(self, calibration: PayloadCalibration) -> None:
        """Replace the payload/bias model (takes effect at once)."""
        self.calibration = calibration
        self.set_pose(self._rot_base_tip)

    def refine_bias(self, fx: float, fy: float, fz: float, tx: float, ty: float, tz: float) -> bool:
        """Feed one out-of-contact raw wrench to the online bias estimator, if any.

        The caller decides when the tool is out of contact (between trials);
        the estimator additionally refuses samples whose force innovation
        exceeds its contact gate.  Returns True when the bias was updated.
        """
        rls = self.rls
        if rls is None:
            return False
        g = self.calibration.gravity_wrench(transpose(mat_mul(self._rot_base_tip, self._rts)))
        b = self.calibration
        # measured minus gravity only (the calibration's own bias added back)
        fb, tb = b.force_bias_n, b.torque_bias_nm
        z = (
            fx - g[0] + fb[0], fy - g[1] + fb[1], fz - g[2] + fb[2],
            tx - g[3] + tb[0], ty - g[4] + tb[1], tz - g[5] + tb[2],
        )
        if not rls.update(z, True):
            return False
        self.calibration = b.with_bias(rls.force_bias_n, rls.torque_bias_nm)
        self.set_pose(self._rot_base_tip)
        return True

    def reset(self) -> None:
        """Empty the filter and drop the output to zero (after a fault reset or re-calibration)."""
        self.filter.reset()
        self.safety.force_zero()

    def step(
        self, fx: float, fy: float, fz: float, tx: float, ty: float, tz: float, enabled: bool, dt_s: float
    ) -> tuple[float, ...]:
        """Run Algorithm 1 on one raw wrench (sensor frame, N and N·m).

        Parameters
        ----------
        fx, fy, fz, tx, ty, tz
            Raw F/T sample.
        enabled
            Haptic feedback on and no fault latched; otherwise the rendered
            force ramps to zero (the rest of the path still runs, for the record).
        dt_s
            Time since the previous tick, s (drives the safety ramps).

        Returns
        -------
        tuple of float
            The stages in :data:`STEP_FIELDS` order: compensated wrench
            (6), filtered force, tip, base and haptic frame force, scaled and
            rendered force (3 each), and ``force_n`` = |filtered force|, the
            magnitude the study task judges.
        """
        o = self._off
        cx = fx - o[0]
        cy = fy - o[1]
        cz = fz - o[2]
        mx, my, mz = self.filter.update(cx, cy, cz)
        r = self._rts
        ax = r[0] * mx + r[1] * my + r[2] * mz
        ay = r[3] * mx + r[4] * my + r[5] * mz
        az = r[6] * mx + r[7] * my + r[8] * mz
        r = self._rbt
        bx = r[0] * ax + r[1] * ay + r[2] * az
        by = r[3] * ax + r[4] * ay + r[5] * az
        bz = r[6] * ax + r[7] * ay + r[8] * az
        r = self._rhb
        hx = r[0] * bx + r[1] * by + r[2] * bz
        hy = r[3] * bx + r[4] * by + r[5] * bz
        hz = r[6] * bx + r[7] * by + r[8] * bz
        sx, sy, sz = scale_components(hx, hy, hz, self._fmax, self._fscale)
        ox, oy, oz = self.safety.step(sx, sy, sz, enabled, dt_s)
        return (
            cx, cy, cz, tx - o[3], ty - o[4], tz - o[5],
            mx, my, mz, ax, ay, az, bx, by, bz, hx, hy, hz,
            sx, sy, sz, ox, oy, oz,
            math.hypot(mx, my, mz),
        )
