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
per-sample path is :func:`step_kernel`, compiled (:mod:`pipeline.core.compiled`): the stages' own kernels
(:func:`pipeline.force.filters.ma3_update`, :func:`pipeline.force.scaling.scale_kernel`,
:func:`pipeline.force.safety.safety_step`) and the three rotations, over one float64 array that holds the whole
state (the framework's :attr:`HapticFramework.array`, of which the filter and the safety stage keep slices).  It is
the hot loop of the product (``haptic-study bench pipeline``), the same code on hardware, in replay and in a
simulated study.  The stage modules own the equations; this one only sequences them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from pipeline.core import exact, tick_record
from pipeline.core.compiled import State, fingerprint, is_warm, kernel, warm_once
from pipeline.force import bias_refinement, filters, frames, safety, scaling
from pipeline.force.bias_refinement import RlsBias
from pipeline.force.config import (
    DEFAULT_ROT_HAPTIC_BASE,
    DEFAULT_ROT_TIP_SENSOR,
    FrameworkConfig,
    framework_config_from_dict,
    framework_config_to_dict,
)
from pipeline.force.filters import MovingAverage3
from pipeline.force.frames import IDENTITY, Mat3, Vec3
from pipeline.force.payload_compensator import NO_PAYLOAD, PayloadCalibration
from pipeline.force.safety import SafetyGovernor

__all__ = [
    "DEFAULT_ROT_HAPTIC_BASE",
    "DEFAULT_ROT_TIP_SENSOR",
    "SNAPSHOT_VERSION",
    "STEP_FIELDS",
    "FrameworkConfig",
    "HapticFramework",
    "framework_config_from_dict",
    "framework_config_to_dict",
    "step_kernel",
]

#: Names of the values :meth:`HapticFramework.step` returns, in order (defined with the tick's record,
#: :data:`pipeline.core.tick_record.STEP_FIELDS`; indices: comp 0–2, filt 3–5, tip 6–8, base 9–11, haptic 12–14,
#: scaled 15–17, render 18–20).
STEP_FIELDS = tick_record.STEP_FIELDS


# The framework's state, one float64 array: the force offsets (payload weight plus bias in the current pose), the
# three rotations ᵀ_S R, ᴮ_T R, ᴴ_B R (row-major), f_scale and f_max, the payload's weight in the current pose and
# the bias (6 each: force N, torque N·m), the safety stage's state, the filter's state.
_OFF, _RTS, _RBT, _RHB, _FSCALE, _FMAX, _PAY, _BIAS = 0, 3, 12, 21, 30, 31, 32, 38
_SAFE = 44
_FILT = _SAFE + safety.STATE_SIZE
#: Where the framework's array keeps the safety stage's ramp gain (the tick's record reads it there).
GAIN_AT = _SAFE + safety.GAIN


def _compile(callees: int) -> Callable[..., tuple[float, ...]]:
    """:func:`step_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the stages it calls (numba
    keys its cache on a kernel's own file and closure)."""

    @kernel
    def step_kernel(st: State, fx: float, fy: float, fz: float, command_n: float, commanded: bool, enabled: bool,
                    dt_s: float) -> tuple[float, ...]:
        """Algorithm 1 on one raw force sample over the framework's array ``st``: :meth:`HapticFramework.step`, or with
        ``commanded`` :meth:`HapticFramework.step_commanded` (``command_n`` rendered instead of the scaled force)."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        cx = fx - st[_OFF]
        cy = fy - st[_OFF + 1]
        cz = fz - st[_OFF + 2]
        mx, my, mz = filters.ma3_update(st[_FILT:], cx, cy, cz)
        # eqs. (TCP), (Base), (Haptic): frames.mat_vec three times
        a = _RTS
        ax = st[a] * mx + st[a + 1] * my + st[a + 2] * mz
        ay = st[a + 3] * mx + st[a + 4] * my + st[a + 5] * mz
        az = st[a + 6] * mx + st[a + 7] * my + st[a + 8] * mz
        b = _RBT
        bx = st[b] * ax + st[b + 1] * ay + st[b + 2] * az
        by = st[b + 3] * ax + st[b + 4] * ay + st[b + 5] * az
        bz = st[b + 6] * ax + st[b + 7] * ay + st[b + 8] * az
        c = _RHB
        hx = st[c] * bx + st[c + 1] * by + st[c + 2] * bz
        hy = st[c + 3] * bx + st[c + 4] * by + st[c + 5] * bz
        hz = st[c + 6] * bx + st[c + 7] * by + st[c + 8] * bz
        qx, qy, qz = scaling.scale_kernel(hx, hy, hz, st[_FMAX], st[_FSCALE])  # eq. (H_scaled)
        g = st[_SAFE:_FILT]
        if commanded:
            # the command along the haptic frame's z in the scaled force's place: the safety stage advances once
            ox, oy, oz = safety.safety_step(g, 0.0, 0.0, command_n, enabled, dt_s)
        else:
            ox, oy, oz = safety.safety_step(g, qx, qy, qz, enabled, dt_s)
        return (cx, cy, cz, mx, my, mz, ax, ay, az, bx, by, bz, hx, hy, hz, qx, qy, qz, ox, oy, oz)

    return step_kernel


@kernel
def offsets_kernel(st: State) -> None:
    """The force offsets the per-tick path subtracts: the payload's weight in this pose plus the bias, from the
    framework's array (after a new pose, a new calibration, a refined bias)."""
    for k in range(3):
        st[_OFF + k] = st[_PAY + k] + st[_BIAS + k]


def _compile_refine(callees: int) -> Callable[..., bool]:
    """:func:`refine_kernel` closed over the fingerprint of :mod:`pipeline.force.bias_refinement`."""

    @kernel
    def refine_kernel(st: State, r: State, fx: float, fy: float, fz: float, tx: float, ty: float, tz: float) -> bool:
        """:meth:`HapticFramework.refine_bias` over the framework's array ``st`` and the estimator's ``r``: the
        sample minus the payload's weight to :func:`pipeline.force.bias_refinement.rls_update`, and on an update
        the new bias and force offsets."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        p = _PAY
        if not bias_refinement.rls_update(r, fx - st[p], fy - st[p + 1], fz - st[p + 2], tx - st[p + 3],
                                          ty - st[p + 4], tz - st[p + 5]):
            return False
        for k in range(6):
            st[_BIAS + k] = r[bias_refinement.THETA + k]
        offsets_kernel(st)
        return True

    return refine_kernel


#: Algorithm 1's tick, compiled (:meth:`HapticFramework.step`).
step_kernel = _compile(fingerprint(exact, frames, filters, safety, scaling))
#: The online bias refinement's step, compiled (:meth:`HapticFramework.refine_bias`).
refine_kernel = _compile_refine(fingerprint(bias_refinement))


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
        "_cal",
        "_mounted",
        "_rbt",
        "_rts",
        "array",
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
        self.filter = MovingAverage3(config.filter_window)
        self.safety = SafetyGovernor(config.safety, device_peak_n)
        self.rls = rls
        if rls is not None:
            rls.reset(calibration.force_bias_n, calibration.torque_bias_nm)
        self._rts = config.rot_tip_sensor
        self._rbt: Mat3 = IDENTITY
        #: The whole state of the per-tick path, as :func:`step_kernel` reads it; the filter and the safety stage keep
        #: their states in slices of it.
        self.array: State = np.zeros(_FILT + filters.state_size(config.filter_window))
        st = self.array
        st[_RTS:_RTS + 9] = config.rot_tip_sensor
        st[_RHB:_RHB + 9] = config.rot_haptic_base
        st[_FSCALE], st[_FMAX] = float(config.f_scale_n), float(config.f_max_n)
        self._bias = (*calibration.force_bias_n, *calibration.torque_bias_nm)
        self.safety.adopt(st[_SAFE:_FILT])
        self.filter.adopt(st[_FILT:])
        self.set_pose(IDENTITY)
        warm_kernels(st)

    def __setstate__(self, state: tuple[None, dict[str, Any]]) -> None:
        """A copy (``copy.deepcopy``, pickle) keeps its filter's and safety stage's states in its own array, as the
        original does (else a reset or a derated clamp would reach a copy of the state the tick never reads)."""
        for name, value in state[1].items():
            object.__setattr__(self, name, value)
        st = self.array
        self.safety.array, self.filter.array = st[_SAFE:_FILT], st[_FILT:]

    def set_pose(self, rot_base_tip: Mat3) -> None:
        """Take a new robot orientation ᴮ_T R (at each robot update, 125 Hz on a CB3).

        Recomputes the payload weight the sensor reads in this pose
        (:meth:`pipeline.force.payload_compensator.MountedPayload.payload_wrench`).
        """
        self._rbt = rot_base_tip
        st = self.array
        st[_RBT:_RBT + 9] = rot_base_tip
        st[_PAY:_PAY + 6] = self._mounted.payload_wrench(rot_base_tip)
        offsets_kernel(st)

    @property
    def rot_base_tip(self) -> Mat3:
        """The robot's orientation the framework holds (:meth:`set_pose`)."""
        return self._rbt

    @property
    def _payload(self) -> tuple[float, ...]:
        """The payload's weight the sensor reads in the current pose (force N, torque N·m)."""
        return tuple(self.array[_PAY:_PAY + 6].tolist())

    @property
    def _bias(self) -> tuple[float, ...]:
        """The sensor's bias now (force N, torque N·m): the calibration's, refined online."""
        return tuple(self.array[_BIAS:_BIAS + 6].tolist())

    @_bias.setter
    def _bias(self, bias: tuple[float, ...]) -> None:
        self.array[_BIAS:_BIAS + 6] = bias

    @property
    def _off(self) -> tuple[float, float, float, float, float, float]:
        """The offsets the raw wrench is compensated by: the payload's weight in this pose plus the bias."""
        p, b = self._payload, self._bias
        return (p[0] + b[0], p[1] + b[1], p[2] + b[2], p[3] + b[3], p[4] + b[4], p[5] + b[5])

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
        """Clamp to the haptic device's current (derated) force limit as well (:meth:`SafetyGovernor.set_device_limit`);
        returns the safety stage."""
        g = self.safety
        g.set_device_limit(device_limit_n)
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
        return refine_kernel(self.array, rls.array, float(fx), float(fy), float(fz), float(tx),
                             float(ty), float(tz))

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
        return step_kernel(self.array, float(fx), float(fy), float(fz), 0.0,
                           False, bool(enabled), float(dt_s))

    def step_commanded(self, fx: float, fy: float, fz: float, command_n: float, enabled: bool,
                       dt_s: float) -> tuple[float, ...]:
        """One tick that renders a commanded force (:class:`pipeline.core.force_program.ForceProgram`) instead of the
        scaled sensor force: the stages up to the scaled force as :meth:`step` computes them (the record keeps what
        the sensor measured), the rendered force the safety stage's output for ``command_n`` along the haptic
        frame's ``z`` -- clamped, slew-limited, faded in and out, ramped to zero by a fault, as any force.

        The stages run as in :meth:`step`, and the safety stage advances once per tick, on the command
        (:func:`step_kernel` with ``commanded``).
        """
        return step_kernel(self.array, float(fx), float(fy), float(fz),
                           float(command_n), True, bool(enabled), float(dt_s))


#: Version of :meth:`HapticFramework.snapshot`'s layout.
SNAPSHOT_VERSION = 1


def warm_kernels(array: State | None = None) -> None:
    """Compile Algorithm 1's kernels (or load them from numba's cache), once a process, on a copy of a framework's
    ``array`` (None: a default framework's, built for it): a framework's construction calls it, so that no tick of a
    running loop waits for a compiler (cold, ~2 s once an installation); so does a parent that forks a process per
    participant, before forking (its children inherit the machine code)."""
    if array is None:
        if not is_warm(__name__):
            HapticFramework(FrameworkConfig(), device_peak_n=3.3)  # (its construction comes back here with its array)
        return

    def compile_them() -> None:
        st = array.copy()
        step_kernel(st, 0.0, 0.0, 0.0, 0.0, False, True, 0.001)
        # and each stage as its Python side calls it (a commanded force's tick, a replay, the figures)
        filters.ma3_update(st[_FILT:], 0.0, 0.0, 0.0)
        filters.ma3_mean(st[_FILT:])
        safety.safety_step(st[_SAFE:_FILT], 0.0, 0.0, 0.0, True, 0.001)
        scaling.scale_kernel(1.0, 0.0, 0.0, 3.0, 7.0)
        scaling.clamp3(1.0, 0.0, 0.0, 3.0)
        exact.hypot3(1.0, 0.0, 0.0)
        exact.fsum(st[:3])
        refine_kernel(st, RlsBias((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)).array, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        offsets_kernel(st)

    warm_once(__name__, compile_them)
