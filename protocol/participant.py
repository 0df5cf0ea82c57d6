"""The simulated participant of the force-regulation study (science.md §4.2).

PLACEHOLDER DOCSTRING -- replaced after calibration.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from pipeline.scaling import scale_magnitude
from pipeline.sim.hand import ArmParams, HandObservation, min_jerk
from pipeline.sim.tissue import TissueParams

__all__ = ["PARAM_RANGES", "ParticipantParams", "SAFE_Y_RANGE_M", "SimulatedParticipant"]

#: The participant never commands an equilibrium outside this range (m along the Touch's +y, from
#: the start pose): 30 mm down is 15 mm into the tissue (≈ 20 N, far beyond any task force) and
#: 5 mm up is just above the start pose.  Keeps a confused model (or NaN input) from making the
#: robot jump.
SAFE_Y_RANGE_M: tuple[float, float] = (-0.030, 0.005)

_CONTACT_VISUAL_M = 0.001  # contact noticed on the camera image at δ > 1 mm
_CONTACT_HAPTIC_N = 0.05  # ... or felt at F > 0.05 N (haptic percept, tissue-force units)
_HOLD_FRACTION = 0.05  # no submovement when |F* − F̂| < 5 % F*
_RETRACT_S = 0.4  # minimum-jerk retraction to the start pose after a trial
_DRIFT_KNOT_S = 0.02  # postural drift: a random walk sampled every 20 ms, linearly interpolated
_HIST = 1024  # observation history (ticks); must cover the longest percept delay
_MASK = _HIST - 1
_NOISE_BLOCK = 1024
# haptic Weber fraction vs displayed force (science.md §4.1: 10–15 % at the GENTLE display of
# 0.257 N, 8–12 % at FIRM's 0.509 N): σ_h·(0.257/f)^0.325, floored at 0.8 σ_h
_DISPLAY_GENTLE_N = 0.257
_WEBER_EXP = 0.325
_WEBER_FLOOR = 0.8


def _trunc_lognormal(rng: np.random.Generator, median: float, sigma: float, k: float = 2.5) -> float:
    """``median · exp(σ z)`` with ``z ~ N(0, 1)`` clipped to ±k (documented, bounded ranges)."""
    z = float(rng.standard_normal())
    z = -k if z < -k else (k if z > k else z)
    return median * math.exp(sigma * z)


@dataclass(frozen=True, slots=True)
class ParticipantParams:
    """Per-participant constants (drawn once from the participant's seed).

    Times in s, lengths in m, forces in N.  :data:`PARAM_RANGES` lists the
    range each value is drawn from; the fixed noise levels and the OFF
    decision-interval factor are class defaults (the calibration's tuning knobs).
    """

    tau_visual_s: float  # perception + decision delay of the visual percept
    camera_latency_s: float  # extra camera + display latency of the visual channel
    tau_haptic_s: float  # perception + decision delay of the haptic percept
    reaction_center_s: float  # centre of the per-trial start reaction time (±0.1 s)
    approach_center_s: float  # centre of the per-trial feed-forward approach duration (±0.1 s)
    submove_s: float  # D: duration of a corrective submovement
    interval_s: float  # T_int: pause between submovements (× off_interval_factor without haptics)
    gain: float  # G: fraction of the perceived error corrected per submovement
    drift_m_per_sqrt_s: float  # postural random walk of the equilibrium point
    bias_off: float  # b: multiplicative bias of the remembered target, haptics OFF
    bias_on: float  # b: multiplicative bias of the remembered target ("trained feel"), haptics ON
    pushback_comp: float  # fraction of the expected haptic push-back the participant pre-compensates
    search_step_m: float  # downward step when the approach ended without noticed contact
    sigma_haptic: float  # per-look log noise of the felt force at the GENTLE display level (0.26 N)

    # fixed model constants (science.md §4.2) -- the tuning knobs
    stiffness_belief_median: float = 0.85  # k̂/k per trial ~ LogN(median, σ)
    stiffness_belief_sigma: float = 0.22
    sigma_visual: float = 0.06  # per-look log noise of the visual percept
    sigma_haptic_model: float = 0.13  # systematic part of the haptic percept's uncertainty (ML weight)
    sigma_gauge: float = 0.03  # per-look log noise of reading a live force gauge (training)
    sigma_mem_off: float = 0.10  # per-trial memory noise of the target, OFF
    sigma_mem_on: float = 0.13  # per-trial memory noise of the target, ON
    surface_sigma_m: float = 0.0025  # per-trial error of the believed surface depth
    off_interval_factor: float = 1.5  # visual checking is slower than feeling
    motor_noise_rel: float = 0.15  # signal-dependent log noise of a submovement amplitude
    motor_noise_abs_m: float = 1.0e-4  # additive submovement noise

    @classmethod
    def draw(cls, rng: np.random.Generator) -> ParticipantParams:
        """Draw one participant's constants (the draw order is part of the seed contract)."""
        u = rng.uniform
        return cls(
            tau_visual_s=float(u(0.18, 0.26)),
            camera_latency_s=float(u(0.05, 0.10)),
            tau_haptic_s=float(u(0.10, 0.14)),
            reaction_center_s=float(u(0.6, 0.9)),
            approach_center_s=float(u(0.6, 0.8)),
            submove_s=float(u(0.20, 0.35)),
            interval_s=float(u(0.15, 0.35)),
            gain=float(u(0.5, 0.9)),
            drift_m_per_sqrt_s=5.0e-5 * float(u(0.6, 1.4)),
            bias_off=_trunc_lognormal(rng, 1.0, 0.15),
            bias_on=_trunc_lognormal(rng, 1.0, 0.05),
            pushback_comp=float(u(0.3, 0.9)),
            search_step_m=float(u(0.001, 0.002)),
            sigma_haptic=float(u(0.10, 0.15)),
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain data (for logs)."""
        return asdict(self)


#: Range of every drawn parameter, ``name: (low, high)`` (inclusive).
PARAM_RANGES: dict[str, tuple[float, float]] = {
    "tau_visual_s": (0.18, 0.26),
    "camera_latency_s": (0.05, 0.10),
    "tau_haptic_s": (0.10, 0.14),
    "reaction_center_s": (0.6, 0.9),
    "approach_center_s": (0.6, 0.8),
    "submove_s": (0.20, 0.35),
    "interval_s": (0.15, 0.35),
    "gain": (0.5, 0.9),
    "drift_m_per_sqrt_s": (3.0e-5, 7.0e-5),
    "bias_off": (math.exp(-2.5 * 0.15), math.exp(2.5 * 0.15)),
    "bias_on": (math.exp(-2.5 * 0.05), math.exp(2.5 * 0.05)),
    "pushback_comp": (0.3, 0.9),
    "search_step_m": (0.001, 0.002),
    "sigma_haptic": (0.10, 0.15),
}

# stages of a trial
_IDLE, _WAIT, _APPROACH, _CONTROL = 0, 1, 2, 3


class SimulatedParticipant:
    """A seeded simulated participant: implements the rig's ``StylusDriver``.

    Parameters
    ----------
    seed
        Seeds every random draw (parameters, per-trial beliefs, percept and
        motor noise); same seed and same observations → same trajectory.
    params
        Use these constants instead of drawing them (the noise still comes from ``seed``).
    tissue
        The tissue the participant has an internal model of (``k``, ``n``);
        also what a live force gauge would show during training.
    arm
        The arm impedance (the participant's model of its own push-back, ``K_a``).
    motion_scale
        Robot displacement per stylus displacement.
    f_max_n, f_scale_n
        Parameters of the haptic scaling law (the pipeline's), used to invert
        the felt force into a tissue-force percept.
    """

    def __init__(
        self,
        seed: int = 0,
        params: ParticipantParams | None = None,
        *,
        tissue: TissueParams | None = None,
        arm: ArmParams | None = None,
        motion_scale: float = 1.0,
        f_max_n: float = 3.0,
        f_scale_n: float = 7.0,
    ) -> None:
        if not (math.isfinite(motion_scale) and motion_scale > 0):
            raise ValueError(f"motion_scale = {motion_scale!r}: must be a finite number > 0")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed = {seed!r}: must be a whole number ≥ 0")
        self.seed = int(seed)
        self._rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(0,)))
        self.params = params if params is not None else ParticipantParams.draw(self._rng)
        self._n_trials = 0
        self._n_practice = 0
        tp = tissue or TissueParams()
        self._k = tp.stiffness_n_per_m_pow
        self._n = tp.exponent
        self._inv_n = 1.0 / tp.exponent
        self._arm_k = (arm or ArmParams()).stiffness_n_per_m
        self._s = float(motion_scale)
        self._fmax = float(f_max_n)
        self._fscale = float(f_scale_n)
        scale_magnitude(1.0, self._fmax, self._fscale)  # validates the law's parameters
        self._z: list[float] = []
        self._zi = 0
        # observation history (ring of the last _HIST ticks)
        self._ht = [-math.inf] * _HIST
        self._hy = [0.0] * _HIST
        self._hf = [0.0] * _HIST
        self._hd = [0.0] * _HIST
        self._hg = [0.0] * _HIST
        self._hi = 0
        self._t = 0.0  # newest valid observation time
        # commanded trajectory: a minimum-jerk segment (y0 → y1 over [t0, t0 + dur])
        self._p_t0 = 0.0
        self._p_dur = 1.0
        self._p_y0 = 0.0
        self._p_y1 = 0.0
        self._p_end = 0.0  # t0 + dur
        # postural drift (random walk, linearly interpolated between knots)
        self._drift_on = False
        self._d_t0 = 0.0
        self._d_t1 = math.inf
        self._d0 = 0.0
        self._d1 = 0.0
        self._d_step = self.params.drift_m_per_sqrt_s * math.sqrt(_DRIFT_KNOT_S)
        self._out = 0.0
        # trial state
        self._pending: tuple[Any, ...] | None = None
        self._stage = _IDLE
        self._next = math.inf
        self._cue_t = 0.0
        self._target = 0.0
        self._true_target = 0.0
        self._khat = self._k
        self._haptic = False
        self._gauge = False
        self._surface_err = 0.0
        self._approach_s = 0.7
        self._period = 0.5
        self._interval = 0.3
        self._delta_star = 0.0
        self.decisions = 0  # decisions taken since construction (for tests and logs)
        self.submovements = 0

    # -- random numbers -------------------------------------------------------------------------
    def _randn(self) -> float:
        i = self._zi
        if i >= len(self._z):
            self._z = self._rng.standard_normal(_NOISE_BLOCK).tolist()
            i = 0
        self._zi = i + 1
        return self._z[i]

    # -- the session runner's interface -------------------------------------------------------
    def begin_trial(self, target_force_n: float, haptic_on: bool, t_s: float) -> None:
        """The target word is shown at ``t_s``: plan the trial.

        The participant's clock for the trial starts at the first observation
        after this call (the tick at which the loop applies the trial's mark),
        so a runner whose ``t_s`` is on another time base cannot desynchronise it.
        """
        self._stage_trial(target_force_n, haptic_on, t_s, gauge=False, practice=False)

    def practice(self, target_force_n: float, haptic_on: bool, t_s: float, live_force_n_visible: bool) -> None:
        """A training trial: like :meth:`begin_trial`; with a live force gauge the visual
        percept is the displayed force with small noise instead of an indentation judged
        through the stiffness belief."""
        self._stage_trial(target_force_n, haptic_on, t_s, gauge=bool(live_force_n_visible), practice=True)

    def end_trial(self, t_s: float) -> None:
        """Retract to the start pose (y_c = 0) with a 0.4 s minimum-jerk move, then idle."""
        self._pending = ("end", float(t_s))

    def _stage_trial(self, target_force_n: float, haptic_on: bool, t_s: float, gauge: bool, practice: bool) -> None:
        f = float(target_force_n)
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f"target_force_n = {target_force_n!r}: must be a finite force > 0")
        self._pending = ("begin", f, bool(haptic_on), float(t_s), gauge, practice)

    @property
    def in_trial(self) -> bool:
        """True between the start of a trial and :meth:`end_trial`."""
        return self._stage != _IDLE

    @property
    def internal_target_n(self) -> float:
        """The force the participant is aiming for in the current trial (biased, noisy), N."""
        return self._target

    # -- StylusDriver ---------------------------------------------------------------------------
    def equilibrium_y(self, obs: HandObservation) -> float:
        """Equilibrium point of the arm, m along the Touch's +y from the start pose."""
        t, y_st, felt, ind, gap = obs
        if not (t - t == 0.0):
            t = self._t  # non-finite time: stand still in time
        elif t > self._t:
            self._t = t
        i = (self._hi + 1) & _MASK
        self._hi = i
        self._ht[i] = t
        self._hy[i] = y_st
        self._hf[i] = felt
        self._hd[i] = ind
        self._hg[i] = gap
        if self._pending is not None:
            self._apply_pending(t)
        if t >= self._next:
            self._event(t)
        # the current plan
        if t >= self._p_end:
            y = self._p_y1
        else:
            y = min_jerk(t, self._p_t0, self._p_dur, self._p_y0, self._p_y1)
        if self._drift_on:
            if t >= self._d_t1:
                self._drift_advance(t)
            y += self._d0 + (self._d1 - self._d0) * (t - self._d_t0) * (1.0 / _DRIFT_KNOT_S)
        if y < -0.030:
            y = -0.030
        elif y > 0.005:
            y = 0.005
        elif not (y == y):  # pragma: no cover - the plan is built from finite values only
            y = self._out
        self._out = y
        return y

    # -- internals ------------------------------------------------------------------------------
    def _plan(self, t0: float, dur: float, y1: float) -> None:
        """Start a minimum-jerk move from the current plan output (without drift) to ``y1``."""
        y0 = self._plan_value(t0)
        lo, hi = SAFE_Y_RANGE_M
        if not (y1 == y1):
            y1 = y0
        y1 = lo if y1 < lo else (hi if y1 > hi else y1)
        self._p_t0, self._p_dur, self._p_y0, self._p_y1 = t0, dur, y0, y1
        self._p_end = t0 + dur

    def _plan_value(self, t: float) -> float:
        if t >= self._p_end:
            return self._p_y1
        return min_jerk(t, self._p_t0, self._p_dur, self._p_y0, self._p_y1)

    def _fold_drift(self, t: float) -> None:
        """Absorb the drift into the plan (so the output stays continuous) and stop it."""
        if self._drift_on:
            d = self._d0 + (self._d1 - self._d0) * min(1.0, (t - self._d_t0) / _DRIFT_KNOT_S)
            self._p_y0 += d
            self._p_y1 += d
        self._drift_on = False
        self._d0 = self._d1 = 0.0

    def _drift_advance(self, t: float) -> None:
        while t >= self._d_t1:
            self._d_t0 = self._d_t1
            self._d0 = self._d1
            self._d1 = self._d0 + self._d_step * self._randn()
            self._d_t1 = self._d_t0 + _DRIFT_KNOT_S

    def _apply_pending(self, t: float) -> None:
        cmd, self._pending = self._pending, None
        assert cmd is not None
        self._fold_drift(t)
        if cmd[0] == "end":
            self._plan(t, _RETRACT_S, 0.0)
            self._stage = _IDLE
            self._next = math.inf
            return
        _, force, haptic, _t_s, gauge, practice = cmd
        p = self.params
        # every trial has its own random stream (common random numbers: trial k's beliefs and
        # noise do not depend on what happened in earlier trials)
        if practice:
            self._n_practice += 1
            key: tuple[int, ...] = (2, self._n_practice)
        else:
            self._n_trials += 1
            key = (1, self._n_trials)
        rng = self._rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=key))
        self._z = []
        self._zi = 0
        self._cue_t = t
        self._haptic = haptic
        self._gauge = gauge
        self._true_target = force
        if haptic:
            self._target = force * p.bias_on * math.exp(p.sigma_mem_on * self._randn())
        else:
            self._target = force * p.bias_off * math.exp(p.sigma_mem_off * self._randn())
        if gauge:  # the gauge shows the target band: nothing to remember
            self._target = force
        zk = self._randn()
        zk = -3.0 if zk < -3.0 else (3.0 if zk > 3.0 else zk)
        self._khat = self._k * p.stiffness_belief_median * math.exp(p.stiffness_belief_sigma * zk)
        zs = self._randn()
        zs = -3.0 if zs < -3.0 else (3.0 if zs > 3.0 else zs)
        self._surface_err = p.surface_sigma_m * zs
        rt = p.reaction_center_s + float(rng.uniform(-0.1, 0.1))
        self._approach_s = p.approach_center_s + float(rng.uniform(-0.1, 0.1))
        self._interval = p.interval_s * (1.0 if (haptic or gauge) else p.off_interval_factor)
        self._period = p.submove_s + self._interval
        self._delta_star = (self._target / self._khat) ** self._inv_n
        # hold where we are until the reaction time has passed
        self._plan(t, 1e-3, self._plan_value(t))
        self._stage = _WAIT
        self._next = t + rt

    def _lookup(self, tq: float) -> int:
        """Index of the newest history sample at or before ``tq`` (not before the cue)."""
        if tq < self._cue_t:
            tq = self._cue_t
        ht = self._ht
        j = self._hi
        for _ in range(_HIST - 1):
            if ht[j] <= tq:
                return j
            jn = (j - 1) & _MASK
            if ht[jn] == -math.inf:
                return j
            j = jn
        return j

    def _inverse_scale(self, felt_n: float) -> float:
        """Tissue force whose rendered magnitude is ``felt_n`` (inverse of :func:`scale_magnitude`)."""
        x = felt_n / self._fmax
        if x <= 0.0:
            return 0.0
        if x >= 0.999:
            x = 0.999
        return self._fscale * math.atanh(x)

    def _depth_for(self, force_n: float) -> float:
        """Believed indentation (m) that produces ``force_n`` under the stiffness belief."""
        return (force_n / self._khat) ** self._inv_n if force_n > 0.0 else 0.0

    def _event(self, t: float) -> None:
        if self._stage == _WAIT:
            self._start_approach(t)
        else:
            self._decide(t)

    def _start_approach(self, t: float) -> None:
        """One feed-forward minimum-jerk move to the believed surface + believed indentation."""
        p = self.params
        j = self._lookup(t - p.tau_visual_s - p.camera_latency_s)
        y_st, gap, ind = self._hy[j], self._hg[j], self._hd[j]
        s = self._s
        if not (y_st - y_st == 0.0):
            y_st = self._plan_value(t)
        if not (gap - gap == 0.0) or gap < 0.0:
            gap = 0.0
        if not (ind - ind == 0.0) or ind < 0.0:
            ind = 0.0
        # believed surface position in stylus coordinates (e > 0: believed deeper than it is)
        surface = y_st - (gap + self._surface_err) / s + ind / s
        y1 = surface - self._delta_star / s
        if self._haptic and not self._gauge:
            y1 -= p.pushback_comp * scale_magnitude(self._target, self._fmax, self._fscale) / self._arm_k
        self._plan(t, self._approach_s, y1)
        self._drift_on = True
        self._d_t0, self._d_t1, self._d0, self._d1 = t, t + _DRIFT_KNOT_S, 0.0, self._d_step * self._randn()
        self._stage = _APPROACH
        self._next = t + self._approach_s + self._interval

    def _decide(self, t: float) -> None:
        """One intermittent decision: perceive (delayed, noisy), then hold or start a submovement."""
        p = self.params
        self.decisions += 1
        self._stage = _CONTROL
        self._next = t + self._period
        # visual percept
        j = self._lookup(t - p.tau_visual_s - p.camera_latency_s)
        d = self._hd[j]
        if not (d - d == 0.0):
            return  # no usable image: wait for the next look
        if d < 0.0:
            d = 0.0
        dn = d**self._n
        if self._gauge:
            f_vis = self._k * dn * math.exp(p.sigma_gauge * self._randn())
            var_v = p.sigma_gauge * p.sigma_gauge
        else:
            f_vis = self._khat * dn * math.exp(p.sigma_visual * self._randn())
            var_v = p.sigma_visual * p.sigma_visual + p.stiffness_belief_sigma * p.stiffness_belief_sigma
        contact = d > _CONTACT_VISUAL_M or (self._gauge and f_vis > _CONTACT_HAPTIC_N)
        f_hat = f_vis
        if self._haptic:
            felt = self._hf[self._lookup(t - p.tau_haptic_s)]
            if felt - felt == 0.0:
                # Weber fraction: σ_h at the GENTLE display level, falling to 0.8 σ_h at FIRM's
                sh = p.sigma_haptic
                if felt > _DISPLAY_GENTLE_N:
                    sh *= max(_WEBER_FLOOR, (_DISPLAY_GENTLE_N / felt) ** _WEBER_EXP)
                f_hap = self._inverse_scale(felt * math.exp(sh * self._randn()))
                var_h = sh * sh + p.sigma_haptic_model * p.sigma_haptic_model
                w_h = var_v / (var_v + var_h)
                f_hat = w_h * f_hap + (1.0 - w_h) * f_vis
                contact = contact or f_hap > _CONTACT_HAPTIC_N
        z_rel = self._randn()
        z_abs = self._randn()
        target = self._target
        s = self._s
        if not contact:
            # the approach ended above the surface: step down and look again
            step = p.search_step_m * math.exp(p.motor_noise_rel * z_rel) + p.motor_noise_abs_m * z_abs
            self._plan(t, p.submove_s, self._p_y1 - step / s)
            self.submovements += 1
            return
        err = target - f_hat
        if abs(err) < _HOLD_FRACTION * target:
            return
        dy = self._depth_for(target) - self._depth_for(f_hat)
        if self._haptic and not self._gauge:
            dy += p.pushback_comp * (
                scale_magnitude(target, self._fmax, self._fscale) - scale_magnitude(f_hat, self._fmax, self._fscale)
            ) / self._arm_k
        dy = p.gain * dy * math.exp(p.motor_noise_rel * z_rel) + p.motor_noise_abs_m * z_abs
        self._plan(t, p.submove_s, self._p_y1 - dy / s)
        self.submovements += 1
