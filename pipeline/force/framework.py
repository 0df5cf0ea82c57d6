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
from typing import Any

from pipeline.core import tick_record
from pipeline.force.bias_refinement import RlsBias
from pipeline.force.filters import MovingAverage3, exact_sum
from pipeline.force.frames import IDENTITY, Mat3, Vec3, check_rotation
from pipeline.force.payload_compensator import NO_PAYLOAD, PayloadCalibration
from pipeline.force.safety import SafetyConfig, SafetyGovernor
from pipeline.force.scaling import _SATURATED_T, _SERIES_T, scale_components

_HYPOT = math.hypot
_TANH = math.tanh
_FSUM = math.fsum
_INF = math.inf

__all__ = [
    "DEFAULT_ROT_HAPTIC_BASE",
    "DEFAULT_ROT_TIP_SENSOR",
    "SNAPSHOT_VERSION",
    "STEP_FIELDS",
    "FrameworkConfig",
    "HapticFramework",
    "framework_config_from_dict",
    "framework_config_to_dict",
]

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


#: Names of the values :meth:`HapticFramework.step` returns, in order (defined with the tick's record,
#: :data:`pipeline.core.tick_record.STEP_FIELDS`; indices: comp 0–2, filt 3–5, tip 6–8, base 9–11, haptic 12–14,
#: scaled 15–17, render 18–20).
STEP_FIELDS = tick_record.STEP_FIELDS


class HapticFramework:
    """The per-tick force path from a raw wrench to the force sent to the device.

    Parameters
    ----------
    config
        Algorithm parameters.
    calibration
        Payload/bias model from :func:`pipeline.commissioning.payload_identification.identify_payload`
        (default: none, compensation is a no-op).
    device_peak_n
        Peak force of the haptic device, N (the safety clamp; the device's own report, or its model's peak:
        :mod:`pipeline.devices.registry`).
    rls
        Optional online bias refinement (science.md §1.4).
    """

    __slots__ = (
        "_bias",
        "_cal",
        "_fmax",
        "_fscale",
        "_ft_safe",
        "_hot",
        "_hot_head",
        "_hot_tail",
        "_mounted",
        "_off",
        "_payload",
        "_rbt",
        "_rhb",
        "_rts",
        "config",
        "device_peak_n",
        "filter",
        "rls",
        "safety",
    )

    def __init__(
        self,
        config: FrameworkConfig,
        calibration: PayloadCalibration = NO_PAYLOAD,
        *,
        device_peak_n: float,
        rls: RlsBias | None = None,
    ) -> None:
        self.config = config
        #: The haptic device's peak force, N (the safety clamp is the smaller of it and f_max).
        self.device_peak_n = float(device_peak_n)
        self._cal = calibration
        self._mounted = calibration.for_mount(config.rot_tip_sensor)
        self._bias: tuple[float, ...] = (*calibration.force_bias_n, *calibration.torque_bias_nm)
        self._payload: tuple[float, ...] = (0.0,) * 6
        self.filter = MovingAverage3(config.filter_window)
        self.safety = SafetyGovernor(config.safety, device_peak_n)
        self.rls = rls
        if rls is not None:
            rls.reset(calibration.force_bias_n, calibration.torque_bias_nm)
        self._fmax = float(config.f_max_n)
        self._fscale = float(config.f_scale_n)
        self._ft_safe = _clamp_free_bound(self.safety)
        self._rts = config.rot_tip_sensor
        self._rhb = config.rot_haptic_base
        self._rbt: Mat3 = IDENTITY
        self._off: tuple[float, float, float, float, float, float] = (0.0,) * 6
        # the parts of the per-tick tuple that no pose or bias change touches
        # (the filter rings are cleared in place by MovingAverage3.reset, so
        # holding them is safe)
        f = self.filter
        self._hot_head: tuple[Any, ...] = (f, f.window, float(f.window), *f._buf, *self._rts)
        self._hot_tail: tuple[Any, ...] = self._tail()
        self.set_pose(IDENTITY)

    def _tail(self) -> tuple[Any, ...]:
        g = self.safety
        return (*self._rhb, self._fscale, self._fmax, g, g._max_dt, g._slew, self._ft_safe)

    def set_pose(self, rot_base_tip: Mat3) -> None:
        """Take a new robot orientation ᴮ_T R (at each robot update, 125 Hz on a CB3).

        Recomputes the payload weight the sensor reads in this pose
        (:meth:`pipeline.force.payload_compensator.MountedPayload.payload_wrench`).
        """
        self._rbt = rot_base_tip
        self._payload = self._mounted.payload_wrench(rot_base_tip)
        self._update_offsets()

    def _update_offsets(self) -> None:
        p, b = self._payload, self._bias
        self._off = off = (p[0] + b[0], p[1] + b[1], p[2] + b[2], p[3] + b[3], p[4] + b[4], p[5] + b[5])
        # Everything the per-tick path reads and never writes, in one tuple
        # (one attribute load and one unpack per tick instead of ~20 loads).
        # Rebuilt whenever one of its parts changes: here, which set_pose and
        # every bias change go through.
        self._hot = (off[0], off[1], off[2], *self._hot_head, *self._rbt, *self._hot_tail)

    def compensated_torque(self, tx: float, ty: float, tz: float) -> Vec3:
        """Raw torque minus the payload moment and torque bias in the current pose, N·m."""
        o = self._off
        return (tx - o[3], ty - o[4], tz - o[5])

    @property
    def calibration(self) -> PayloadCalibration:
        """The payload model in use, with the current (possibly refined) bias."""
        b = self._bias
        cal = self._cal
        if (b[0], b[1], b[2]) == tuple(cal.force_bias_n) and (b[3], b[4], b[5]) == tuple(cal.torque_bias_nm):
            return cal
        return cal.with_bias(b[:3], b[3:])

    def set_calibration(self, calibration: PayloadCalibration) -> None:
        """Replace the payload/bias model (takes effect at once; restarts bias refinement from it)."""
        self._cal = calibration
        self._mounted = calibration.for_mount(self._rts)
        self._bias = (*calibration.force_bias_n, *calibration.torque_bias_nm)
        if self.rls is not None:
            self.rls.reset(calibration.force_bias_n, calibration.torque_bias_nm)
        self.set_pose(self._rbt)

    def set_device_limit(self, device_limit_n: float) -> SafetyGovernor:
        """Clamp to the haptic device's current (derated) force limit as well (:meth:`SafetyGovernor.set_device_limit`).

        Rebuilds the per-tick tuple (its clamp-free bound depends on the limit); returns the safety stage.
        """
        g = self.safety
        g.set_device_limit(device_limit_n)
        self._ft_safe = _clamp_free_bound(g)
        self._hot_tail = self._tail()
        self._update_offsets()
        return g

    def refine_bias(self, fx: float, fy: float, fz: float, tx: float, ty: float, tz: float) -> bool:
        """Feed one out-of-contact raw wrench to the online bias estimator, if any.

        The caller decides when the tool is out of contact (between trials);
        the estimator additionally refuses samples whose force innovation
        exceeds its contact gate.  Returns True when the bias was updated.
        """
        rls = self.rls
        if rls is None:
            return False
        p = self._payload
        if not rls.update((fx - p[0], fy - p[1], fz - p[2], tx - p[3], ty - p[4], tz - p[5]), True):
            return False
        self._bias = (*rls.force_bias_n, *rls.torque_bias_nm)
        self._update_offsets()
        return True

    def reset(self) -> None:
        """Empty the filter and drop the output to zero (after a fault reset or re-calibration)."""
        self.filter.reset()
        self.safety.force_zero()

    # -- replay: the whole state, exactly -------------------------------------------------------------
    def snapshot(self) -> dict[str, Any]:
        """Everything the next :meth:`step` depends on, JSON-safe and exact (floats round-trip by ``repr``).

        :meth:`restore` builds a framework that continues bit for bit from here:
        what a recorded session needs to be replayed through this code.
        """
        return {
            "version": SNAPSHOT_VERSION,
            "config": framework_config_to_dict(self.config),
            "device_peak_n": self.device_peak_n,
            "calibration": self._cal.to_dict(),
            "bias": list(self._bias),
            "rls": None if self.rls is None else self.rls.state(),
            "filter": self.filter.state(),
            "safety": self.safety.state(),
            # the haptic device's derated force limit as the loop last passed it on (None: none given or not
            # finite); the raw value, so a replay with another f_max clamps as that f_max would have
            "device_limit_n": lim if math.isfinite(lim := self.safety.device_limit_n) else None,
            "rot_base_tip": list(self._rbt),
        }

    @classmethod
    def restore(cls, snap: dict[str, Any], config: FrameworkConfig | None = None) -> HapticFramework:
        """A framework in the exact state of a :meth:`snapshot`.

        ``config`` replaces the stored configuration (replay "what if" with
        another filter window, f_scale or f_max): the state that does not fit
        it -- the filter's window -- then starts empty, as after a reset.

        Raises
        ------
        ValueError
            A snapshot of another version, or one that does not read.
        """
        if snap.get("version") != SNAPSHOT_VERSION:
            raise ValueError(f"framework snapshot version = {snap.get('version')!r}: "
                             f"this code reads {SNAPSHOT_VERSION}")
        stored = framework_config_from_dict(snap["config"])
        cfg = stored if config is None else config
        cal = PayloadCalibration.from_dict(snap["calibration"])
        rls = None if snap["rls"] is None else RlsBias.from_state(snap["rls"])
        fw = cls(cfg, cal, device_peak_n=float(snap["device_peak_n"]), rls=None)
        fw.rls = rls  # not reset: it continues from its own state
        fw._bias = tuple(float(v) for v in snap["bias"])
        if cfg.filter_window == stored.filter_window:
            fw.filter.load_state(snap["filter"])
        device_limit = snap.get("device_limit_n")  # (absent in snapshots from before thermal derating)
        if device_limit is not None:
            fw.set_device_limit(float(device_limit))  # before the safety state: the state was clamped by it already
        fw.safety.load_state(snap["safety"])
        fw.set_pose(tuple(float(v) for v in snap["rot_base_tip"]))  # type: ignore[arg-type]  # nine items: mypy cannot count a generator
        return fw

    def step(self, fx: float, fy: float, fz: float, enabled: bool, dt_s: float) -> tuple[float, ...]:
        """Run Algorithm 1 on one raw force sample (sensor frame, N).

        Only forces are fed back (paper §IV), so the torques of the sample do
        not enter the per-tick path; :meth:`compensated_torque` gives them
        compensated when a display needs them.

        Parameters
        ----------
        fx, fy, fz
            Raw F/T sample, force part.
        enabled
            Haptic feedback on and no fault latched; otherwise the rendered
            force ramps to zero (the rest of the path still runs, for the record).
        dt_s
            Time since the previous tick, s (drives the safety ramps).

        Returns
        -------
        tuple of float
            The stages in :data:`STEP_FIELDS` order: compensated force,
            filtered force, tip, base and haptic frame force, scaled and
            rendered force (3 each).
        """
        # One function on purpose, though over 80 lines: this is the per-tick hot path.  The same
        # arithmetic as four stage helpers (moving average, the three rotations, scaling, safety)
        # measured 1.89–2.01 µs per tick against 1.57–1.71 µs fused (medians of 21 runs over 20 000
        # recorded ticks, thread CPU time, bench.pipeline_bench's harness, four repetitions): about
        # +0.3 µs, a fifth more per tick.  Only the once-per-window re-sum, which is not per tick, is
        # out of line (_resum_window).
        (
            o0, o1, o2, f, w, wf, bx, by, bz,
            a0, a1, a2, a3, a4, a5, a6, a7, a8,
            b0, b1, b2, b3, b4, b5, b6, b7, b8,
            c0, c1, c2, c3, c4, c5, c6, c7, c8,
            fscale, fmax, g, max_dt, slew, ft_safe,
        ) = self._hot
        cx = fx - o0
        cy = fy - o1
        cz = fz - o2
        # -- moving average: the steady-state path of MovingAverage3.update,
        # written out (same arithmetic, same state).  The running sums are
        # formed first and one finiteness test of their total stands for both
        # of update's tests: a finite total means a finite sample and no
        # overflow.  A non-finite total (a rejected sample, an overflowing
        # window, or merely a total beyond DBL_MAX) leaves the state untouched
        # and takes the method, which redoes this tick exactly; so do the
        # first W samples.
        sx, sy, sz, i, n = f._st
        if n == w:
            sx += cx - bx[i]
            sy += cy - by[i]
            sz += cz - bz[i]
            m = sx + sy + sz
            if m - m == 0.0:
                bx[i] = cx
                by[i] = cy
                bz[i] = cz
                i += 1
                if i < w:
                    f._st = (sx, sy, sz, i, n)
                    mx = sx / wf  # n == w: a float divisor gives the same quotient, faster
                    my = sy / wf
                    mz = sz / wf
                else:  # once per window
                    mx, my, mz = _resum_window(f, wf)
            else:
                mx, my, mz = f.update(cx, cy, cz)
        else:
            mx, my, mz = f.update(cx, cy, cz)
        # -- eqs. (TCP), (Base), (Haptic): frames.mat_vec three times, in place
        ax = a0 * mx + a1 * my + a2 * mz
        ay = a3 * mx + a4 * my + a5 * mz
        az = a6 * mx + a7 * my + a8 * mz
        bx_ = b0 * ax + b1 * ay + b2 * az
        by_ = b3 * ax + b4 * ay + b5 * az
        bz_ = b6 * ax + b7 * ay + b8 * az
        hx = c0 * bx_ + c1 * by_ + c2 * bz_
        hy = c3 * bx_ + c4 * by_ + c5 * bz_
        hz = c6 * bx_ + c7 * by_ + c8 * bz_
        # -- eq. (H_scaled): scaling.scale_components' general branch in place;
        # zero, tiny, huge, saturated and non-finite inputs take the function.
        fmag = _HYPOT(hx, hy, hz)
        t = fmag / fscale
        if t >= _SERIES_T and t <= _SATURATED_T:
            ft = fmax * _TANH(t)
            k = ft / fmag
            qx = hx * k
            qy = hy * k
            qz = hz * k
        else:
            qx, qy, qz = scale_components(hx, hy, hz, fmax, fscale)
            # SafetyGovernor.step's clamp test, done here (q is finite)
            ft = 0.0 if qx * qx + qy * qy + qz * qz <= g._lim2 else _INF
        # -- safety: SafetyGovernor.step's steady state (enabled, fully ramped
        # in, in range, clamp and slew not limiting) in place; everything else
        # the method.  ft ≤ ft_safe proves the clamp inactive (see
        # _clamp_free_bound), so the fused path need not form |q|².
        if enabled and ft <= ft_safe and g.gain == 1.0 and dt_s > 0.0 and dt_s <= max_dt:
            px = g._sx
            py = g._sy
            pz = g._sz
            dx = qx - px
            dy = qy - py
            dz = qz - pz
            step = slew * dt_s
            if dx * dx + dy * dy + dz * dz <= step * step:
                g._sx = ox = px + dx
                g._sy = oy = py + dy
                g._sz = oz = pz + dz
            else:
                ox, oy, oz = g.step(qx, qy, qz, enabled, dt_s)
        else:
            ox, oy, oz = g.step(qx, qy, qz, enabled, dt_s)
        return (
            cx, cy, cz,
            mx, my, mz, ax, ay, az, bx_, by_, bz_, hx, hy, hz,
            qx, qy, qz, ox, oy, oz,
        )

    def step_commanded(self, fx: float, fy: float, fz: float, command_n: float, enabled: bool,
                       dt_s: float) -> tuple[float, ...]:
        """One tick that renders a commanded force (:class:`pipeline.core.force_program.ForceProgram`) instead of the
        scaled sensor force: the stages up to the scaled force as :meth:`step` computes them (the record keeps what
        the sensor measured), the rendered force the safety stage's output for ``command_n`` along the haptic
        frame's ``z`` -- clamped, slew-limited, faded in and out, ramped to zero by a fault, as any force.

        :meth:`step` runs as ever and its safety stage's state is put back before the command takes its place, so
        the stage advances once per tick (the fused step's state is the governor's own: :meth:`SafetyGovernor.state`).
        """
        g = self.safety
        before = g.state()
        stages = self.step(fx, fy, fz, enabled, dt_s)
        g.load_state(before)
        ox, oy, oz = g.step(0.0, 0.0, command_n, enabled, dt_s)
        return (*stages[:-3], ox, oy, oz)


#: Version of :meth:`HapticFramework.snapshot`'s layout.
SNAPSHOT_VERSION = 1


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


def _resum_window(f: MovingAverage3, wf: float) -> Vec3:
    """The fused step's once-per-window exact re-sum of a full window: :meth:`MovingAverage3.update`'s.

    Called with the window's last sample stored; sets the state as ``update``
    would (running sums re-summed exactly, index back to 0) and returns the
    mean.  Out of :meth:`HapticFramework.step` because it runs once per
    window, not per tick.
    """
    bx, by, bz = f._buf
    n = f._st[4]
    try:
        sx = _FSUM(bx)
        sy = _FSUM(by)
        sz = _FSUM(bz)
    except OverflowError:  # filters.exact_sum's fallback, for sums beyond DBL_MAX
        sx, sy, sz = exact_sum(bx), exact_sum(by), exact_sum(bz)
    f._st = (sx, sy, sz, 0, n)
    m = sx + sy + sz
    if m - m == 0.0:
        return (sx / wf, sy / wf, sz / wf)
    return f.mean  # the exact re-sum overflowed


def _clamp_free_bound(g: SafetyGovernor) -> float:
    """Largest ``f_max·tanh(t)`` for which SafetyGovernor.step surely does not clamp.

    The fused scaling forms ``k = ft/|h|`` and ``q = h·k`` with
    ``ft = f_max·tanh(|h|/f_scale)``; each of the roundings in ``hypot``,
    ``k``, ``q_i``, the squares and their sum is below 2⁻⁵² relatively, so the
    computed ``|q|²`` is below ``ft²·(1 + 12·2⁻⁵²)`` (plus subnormal residues far
    below any limit).  With ``ft`` a relative 1e-9 under the clamp radius that
    is below ``_lim2`` whatever the roundings, so the clamp test ``|q|² > _lim2``
    is certainly false and need not be evaluated.  Forces within 1e-9 of the
    radius (|h| ≳ 10·f_scale at the paper's limits) take the full method.
    """
    return g._lim_inner * (1.0 - 1e-9)
