"""The simulated participant of the force-regulation study (science.md §4.2, calibrated).

A :class:`SimulatedParticipant` is the rig's ``StylusDriver``: every tick the
rig calls :meth:`~SimulatedParticipant.equilibrium_y` with a
:class:`pipeline.sim.hand.HandObservation`; the answer is the equilibrium point
``y_c`` of the compliant arm (m along the Touch's +y, from the start pose;
pressing = negative).  The arm physics, robot, tissue and force path are the
rig's; the participant only decides where the hand wants to be.

Model (intermittent submovement control through an equilibrium-point arm,
driven by delayed, biased, noisy force percepts):

* **Percepts** (sampled at each decision from a 1024-tick observation history,
  and never from before the cue):

  - visual, delayed ``τ_v + camera``: ``F̂_v = k̂·δⁿ·e^{N(0,σ_v)}``, ``δ`` = visible
    indentation, per-trial stiffness belief ``k̂ = k·LogN(median 0.85, σ 0.40)``;
  - haptic (feedback ON only), delayed ``τ_h``: the felt rendered force with
    per-look log noise ``σ_h``, mapped back to tissue force by inverting the
    pipeline's tanh law (f_max 3 N, f_scale 7 N; :func:`pipeline.force.scaling.scale_magnitude`
    is the forward law); ``σ_h`` is the participant's Weber fraction at the
    GENTLE display (0.257 N), falling as ``(0.257/f)^0.325`` to 0.8 σ_h at FIRM's
    0.509 N;
  - maximum-likelihood combination weighted by total uncertainty:
    ``w_h = σ_v,tot²/(σ_v,tot² + σ_h,tot²)``, ``σ_v,tot² = σ_v² + σ_k²``, ``σ_h,tot² = σ_h² + 0.13²``;
  - contact is noticed visually at ``δ > 1 mm`` or haptically at ``F̂_h > 0.05 N``.

* **Internal target** ``F* = F_target·b·e^{N(0,σ_mem)}``: OFF ``b ~ LogN(1, 0.15)``,
  ``σ_mem = 0.10``; ON ``b ~ LogN(1, 0.05)``, ``σ_mem = 0.13``.

* **Control.** After a reaction time, one feed-forward minimum-jerk approach
  (:func:`pipeline.sim.hand.min_jerk`), 1.1–1.7 s long (× 1.75 with feedback OFF: contact
  cannot be felt), to the believed surface (the visible gap plus a per-trial depth error
  σ 4.3 mm) plus the believed target indentation
  ``(F*/k̂)^{1/n}``; with feedback ON the participant also pre-compensates a
  fraction ``c_pb`` of the arm's expected push-back ``f_H(F*)/K_a``.  Without
  feedback the approach is watched on the image (every 20 ms, delayed ``τ_v +
  camera``) while it moves, and stopped where it is once the seen force ``k̂·δⁿ``
  passes 1.5 ``F*`` (:mod:`pipeline.sim.approach`, model version 3).  Then a
  decision every ``D + T_int`` (``T_int × 4`` with feedback OFF): hold if
  ``|F* − F̂| < 5 % F*``; if no contact is noticed, step down by the search
  step; otherwise a submovement of duration ``D`` by
  ``Δy = G·[δ̂(F*) − δ̂(F̂) + c_pb·(f_H(F*) − f_H(F̂))/K_a]/s`` (ON term only with
  feedback), times ``e^{N(0,0.15)}`` plus ``N(0, 0.1 mm)``.  Postural drift: a random
  walk of the equilibrium (knots every 20 ms, linearly interpolated) during trials.

Trial interface (the session runner's, :class:`pipeline.core.aim.TrialParticipant`; what a trial asks is the
task's :class:`pipeline.core.aim.TrialAim`)::

    p = SimulatedParticipant(seed=7)                      # or params=ParticipantParams.draw(rng)
    rig.set_driver(p)
    p.begin_trial(TrialAim.constant(target_force_n, haptic_on), t_s)   # cue shown
    p.end_trial(t_s)                                      # 0.4 s min-jerk back to y_c = 0, then idle
    p.begin_trial(TrialAim.constant(target_force_n, haptic_on, gauge=True, practice=True), t_s)  # training trial

``begin_trial``/``end_trial`` only stage the command; it takes
effect at the next observation (the tick at which the loop applies the
trial's ``Mark``), so the participant's clock cannot drift from the trial's
even if ``t_s`` is on another time base.  With a live gauge (``aim.gauge``) the
visual percept is the displayed force ``k·δⁿ`` with log noise 0.03 and the
target is the displayed one (no memory noise).  This is a model of force
*regulation*: it aims at a force that does not move over the trial; an aim whose
target moves is a tracking trial, handed to the tracking hand of :mod:`pipeline.sim.tracking_hand` (the same
person's constants, its own model) until the trial ends.

Determinism: all randomness comes from ``numpy.random.default_rng`` seeded
from ``seed`` (no global state).  Parameters come from one stream; every trial
has its own stream (``SeedSequence(seed, spawn_key=(1, k))`` for the k-th
trial, ``(2, k)`` for the k-th practice trial), so trial k's beliefs and noise
do not depend on how earlier trials went (common random numbers: the same
seed gives trial k the same stiffness belief, surface error and timing in
both modes).

Safety: the commanded equilibrium is clamped to :data:`SAFE_Y_RANGE_M`
= [−30 mm, +5 mm] (30 mm down is 15 mm into the tissue); non-finite or
out-of-range observations are ignored or clipped (a NaN image is "no look", a
NaN time "no time passes", a jump of the time base by > 0.5 s shifts every
internal time), so ``equilibrium_y`` always returns a finite value and never
jumps.  Cost: ≈ 0.3–0.9 µs per call (1–2.5 µs on a loaded 2-vCPU VM); decisions
happen every 0.35–1.75 s (and an OFF approach's movement is looked at every 20 ms),
between them the current minimum-jerk value is returned.

The participant's constants, the population they are drawn from, the
deviations from the model's sources and the calibration against the paper
are in :mod:`pipeline.sim.participant_params`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pipeline.core.aim import TrialAim, TrialQuestion
from pipeline.force.scaling import scale_magnitude
from pipeline.sim.approach import approach_end_y, seen_over_aim
from pipeline.sim.discrimination_observer import DiscriminationObserver
from pipeline.sim.experience import with_profile
from pipeline.sim.hand import ArmParams, HandObservation, min_jerk
from pipeline.sim.learning import Practice, practised
from pipeline.sim.participant_params import ParticipantParams
from pipeline.sim.participant_tick import (
    DRIFT_KNOT_S,
    NEXT_AT,
    T_AT,
    TickState,
    plan_kernel,
    remember_kernel,
    warm_kernels,
)
from pipeline.sim.percepts import inverse_scale, newest_at, weber_sigma
from pipeline.sim.tissue import TissueParams
from pipeline.sim.tracking_hand import TrackingHand

__all__ = ["SAFE_Y_RANGE_M", "SimulatedParticipant"]

#: The participant never commands an equilibrium outside this range (m along the Touch's +y, from
#: the start pose): 30 mm down is 15 mm into the tissue (≈ 20 N, far beyond any task force) and
#: 5 mm up is just above the start pose.  Keeps a confused model (or NaN input) from making the
#: robot jump.
SAFE_Y_RANGE_M: tuple[float, float] = (-0.030, 0.005)

_CONTACT_VISUAL_M = 0.001  # contact noticed on the camera image at δ > 1 mm
_CONTACT_HAPTIC_N = 0.05  # ... or felt at F > 0.05 N (haptic percept, tissue-force units)
_HOLD_FRACTION = 0.05  # no submovement when |F* − F̂| < 5 % F*
_RETRACT_S = 0.4  # minimum-jerk retraction to the start pose after a trial
_NOISE_BLOCK = 1024


# stages of a trial
_IDLE, _WAIT, _APPROACH, _CONTROL = 0, 1, 2, 3

class SimulatedParticipant(TickState):
    """A seeded simulated participant: implements the rig's ``StylusDriver``.

    Its per-tick state is a float64 array (:attr:`array`; the attributes below backed by it), its observation history
    another (:attr:`history`, one row per quantity) and its drawn normals a third, so that the tick between its events
    is two compiled calls (:func:`remember_kernel`, :func:`plan_kernel`), which a caller running ticks in a block
    calls too.

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
    profile
        ``novice`` (the calibrated participant) or ``experienced`` (the same draws, its OFF handicaps reduced as
        :mod:`pipeline.sim.experience` documents).
    practice
        Where in a schedule of visits the session is (:mod:`pipeline.sim.learning`): from the second visit on, the
        participant has learned by the documented rule; None (or the first visit): the calibrated participant.
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
        profile: str = "novice",
        practice: Practice | None = None,
    ) -> None:
        if not (math.isfinite(motion_scale) and motion_scale > 0):
            raise ValueError(f"motion_scale = {motion_scale!r}: must be a finite number > 0")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed = {seed!r}: must be a whole number ≥ 0")
        self.init_tick_state()
        self.seed = int(seed)
        self._rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(0,)))
        self.params = practised(with_profile(params if params is not None else ParticipantParams.draw(self._rng),
                                             profile), practice)
        self.profile = profile
        self._stream = practice.stream() if practice is not None else ()  # a later visit's trials: its own noise
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
        self._zi = 0
        self._nz = 0
        self._hi = 0
        self._t = math.nan  # time of the newest observation (NaN before the first)
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
        self._d_step = self.params.drift_m_per_sqrt_s * math.sqrt(DRIFT_KNOT_S)
        self._out = 0.0
        # trial state
        self._pending: tuple[Any, ...] | None = None
        self._tracking: TrackingHand | None = None  # the hand of a tracking trial (a target that moves)
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
        self._watched = False
        self.decisions = 0  # decisions taken since construction (for tests and logs)
        self.submovements = 0
        warm_kernels()

    def __setstate__(self, state: dict[str, Any]) -> None:
        """An unpickled participant (sent to the loop's own process) has its kernels compiled, or loaded from numba's
        cache, before its first tick, as a built one has."""
        self.__dict__.update(state)
        warm_kernels()

    @property
    def between_events(self) -> bool:
        """Whether its next ticks are its compiled tick until :data:`NEXT_AT` (no trial being staged, no tracking
        trial's hand): what a caller running ticks in a block checks before one."""
        return self._pending is None and self._tracking is None

    # -- random numbers -------------------------------------------------------------------------
    def _randn(self) -> float:
        i = self._zi
        if i >= self._nz:
            self._z = self._rng.standard_normal(_NOISE_BLOCK)
            self._nz = _NOISE_BLOCK
            i = 0
        self._zi = i + 1
        return float(self._z[i])

    def more_normals(self) -> None:
        """Draw the next block of normals behind those left (the same stream, in the same order, as one at a time:
        consecutive draws of one generator): :func:`plan_kernel` asked for more than are left."""
        self._z = np.concatenate((self._z[self._zi:self._nz], self._rng.standard_normal(_NOISE_BLOCK)))
        self._zi = 0
        self._nz = len(self._z)

    # -- the session runner's interface (pipeline.core.aim.TrialParticipant) --------------------
    def begin_trial(self, aim: TrialAim, t_s: float) -> None:
        """The target word is shown at ``t_s``: plan the trial ``aim`` asks for.

        The participant's clock for the trial starts at the first observation
        after this call (the tick at which the loop applies the trial's mark),
        so a runner whose ``t_s`` is on another time base cannot desynchronise it.
        A training trial (``aim.practice``) draws from its own stream; with a live
        force gauge (``aim.gauge``) the visual percept is the displayed force with
        small noise instead of an indentation judged through the stiffness belief.
        """
        f = aim.steady_n
        if f is None:  # a target that moves: the tracking hand's trial
            self._pending = ("track", aim)
            return
        if f == 0.0:  # the stylus held still while the device presents a force (discrimination): at rest
            self._pending = ("end", float(t_s))
            return
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f"target_force_n = {f!r}: must be a finite force > 0")
        self._pending = ("begin", f, aim.haptic_on, float(t_s), aim.gauge, aim.practice)

    def answer(self, question: TrialQuestion) -> str:
        """A two-interval question (force discrimination): which felt stronger, ``"1"`` or ``"2"``, by this
        participant's own perception (:class:`pipeline.sim.discrimination_observer.DiscriminationObserver`, drawn
        from its seed: its Weber fraction and lapse rate)."""
        first, second = question.felt_n
        return str(self.observer.answer(first, second, 0, question.trial_index))

    @property
    def observer(self) -> DiscriminationObserver:
        """This participant's force perception (its own draws, apart from its hand's)."""
        return DiscriminationObserver.drawn(self.seed, 0)

    def end_trial(self, t_s: float) -> None:
        """Retract to the start pose (y_c = 0) with a 0.4 s minimum-jerk move, then idle."""
        self._pending = ("end", float(t_s))

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
        ps = self.array
        dt = t - ps.item(T_AT)
        if -0.5 <= dt <= 0.5:  # False for NaN: the rig never steps more than 10 ms
            ps[T_AT] = t
        else:
            t = self._time_jump(t, dt)
        t = float(t)  # (the kernels are compiled for floats)
        remember_kernel(ps, self.history, t, float(y_st), float(felt), float(ind), float(gap))
        if self._pending is not None:
            self._apply_pending(t)
        if self._tracking is not None:
            y = self._out = min(max(self._tracking.equilibrium_y(obs._replace(t_s=t)), -0.030), 0.005)
            return y
        if t >= ps.item(NEXT_AT):
            self._event(t)
        # the current plan, its drift and its clamp
        y = plan_kernel(ps, self._z, t)
        if y != y:  # the drift's knots due need more normals than are drawn
            self.more_normals()
            y = plan_kernel(ps, self._z, t)
        return y  # type: ignore[no-any-return]  # (a kernel's float)

    # -- internals ------------------------------------------------------------------------------
    def _plan(self, t0: float, dur: float, y1: float) -> None:
        """Start a minimum-jerk move from the current plan output (without drift) to ``y1``."""
        y0 = self._plan_value(t0)
        lo, hi = SAFE_Y_RANGE_M
        if y1 != y1:
            y1 = y0
        y1 = lo if y1 < lo else (hi if y1 > hi else y1)
        self._p_t0, self._p_dur, self._p_y0, self._p_y1 = t0, dur, y0, y1
        self._p_end = t0 + dur

    def _plan_value(self, t: float) -> float:
        if t >= self._p_end:
            return self._p_y1
        return min_jerk(float(t), self._p_t0, self._p_dur, self._p_y0, self._p_y1)

    def _fold_drift(self, t: float) -> None:
        """Absorb the drift into the plan (so the output stays continuous) and stop it."""
        if self._drift_on:
            d = self._d0 + (self._d1 - self._d0) * min(1.0, (t - self._d_t0) / DRIFT_KNOT_S)
            self._p_y0 += d
            self._p_y1 += d
        self._drift_on = False
        self._d0 = self._d1 = 0.0

    def _time_jump(self, t: float, dt: float) -> float:
        """A non-finite time, or a jump of more than 0.5 s (another time base): stay continuous.

        Non-finite or absurd times (beyond ±1e6 s of the last one) are ignored -- the
        participant stands still in time.  A plausible jump shifts every internal time
        by the jump, as if the clock had been re-based.
        """
        last = self._t
        if last != last:  # first observation
            self._t = t if (t - t == 0.0 and abs(t) < 1e12) else 0.0
            return self._t
        if not (-1e6 <= dt <= 1e6):
            return last
        self._p_t0 += dt
        self._p_end += dt
        self._d_t0 += dt
        self._d_t1 += dt
        self._next += dt
        self._cue_t += dt
        ht = self._ht
        ht += dt  # (each time plus dt, as one at a time)
        self._t = t
        return t

    def _apply_pending(self, t: float) -> None:
        cmd, self._pending = self._pending, None
        assert cmd is not None
        self._fold_drift(t)
        if self._tracking is not None:  # the tracking trial ends: the plan starts where its hand is
            self._plan(t, 1e-3, self._tracking.value())
            self._p_y0 = self._p_y1 = self._out
            self._tracking = None
        if cmd[0] == "track":
            self._start_tracking(cmd[1], t)
            return
        if cmd[0] == "end":
            self._plan(t, _RETRACT_S, 0.0)
            self._stage = _IDLE
            self._next = math.inf
            return
        _, force, haptic, _t_s, gauge, practice = cmd
        p = self.params
        rng = self._rng = self._trial_stream(practice)
        self._z = np.zeros(0)
        self._zi = self._nz = 0
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
        feel = haptic or gauge  # the force is felt or shown: no slower, visual-only checking
        approach_s = p.approach_center_s + float(rng.uniform(-0.1, 0.1))
        self._approach_s = approach_s * (1.0 if feel else p.off_approach_factor)
        self._interval = p.interval_s * (1.0 if feel else p.off_interval_factor)
        self._watched = not feel
        self._period = p.submove_s + self._interval
        self._delta_star = (self._target / self._khat) ** self._inv_n
        # hold where we are until the reaction time has passed
        self._plan(t, 1e-3, self._plan_value(t))
        self._stage = _WAIT
        self._next = t + rt

    def _start_tracking(self, aim: TrialAim, t: float) -> None:
        """A tracking trial: its own random stream (the trial's, as a regulation trial's) and the tracking hand."""
        rng = self._trial_stream(aim.practice)
        self._cue_t, self._haptic, self._gauge = t, aim.haptic_on, aim.gauge
        self._stage, self._next = _CONTROL, math.inf
        self._tracking = TrackingHand(aim, self.params, rng, t, self._plan_value(t), stiffness=self._k,
                                      exponent=self._n, arm_k=self._arm_k, motion_scale=self._s,
                                      f_max_n=self._fmax, f_scale_n=self._fscale)

    def _trial_stream(self, practice: bool) -> np.random.Generator:
        """The next trial's own random stream (common random numbers: trial k's beliefs and noise do not depend on
        what happened in earlier trials); practice trials count apart."""
        if practice:
            self._n_practice += 1
            key: tuple[int, ...] = (2, self._n_practice)
        else:
            self._n_trials += 1
            key = (1, self._n_trials)
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=key + self._stream))

    def _lookup(self, tq: float) -> int:
        """Index of the newest history sample at or before ``tq`` (not before the cue)."""
        return newest_at(self._ht, self._hi, float(tq), self._cue_t)

    def _depth_for(self, force_n: float) -> float:
        """Believed indentation (m) that produces ``force_n`` under the stiffness belief."""
        return (force_n / self._khat) ** self._inv_n if force_n > 0.0 else 0.0

    def _event(self, t: float) -> None:
        if self._stage == _WAIT:
            self._start_approach(t)
        elif self._stage == _APPROACH and self._watched and t < self._p_end + self._interval:  # a look at it
            self._watch(t)
        else:
            self._decide(t)

    def _start_approach(self, t: float) -> None:
        """One feed-forward minimum-jerk move to the believed surface + believed indentation."""
        p = self.params
        j = self._lookup(t - p.tau_visual_s - p.camera_latency_s)
        y_st = float(self._hy[j])
        if not (-0.1 <= y_st <= 0.1):  # also NaN: trust the own command instead
            y_st = self._plan_value(t)
        pushback = 0.0
        if self._haptic and not self._gauge:
            pushback = p.pushback_comp * scale_magnitude(self._target, self._fmax, self._fscale) / self._arm_k
        self._plan(t, self._approach_s, approach_end_y(y_st, float(self._hg[j]), float(self._hd[j]), self._surface_err,
                                                       self._delta_star, self._s, pushback))
        self._drift_on = True
        self._d_t0, self._d_t1, self._d0, self._d1 = t, t + DRIFT_KNOT_S, 0.0, self._d_step * self._randn()
        self._stage = _APPROACH
        self._next = self._p_end + self._interval  # the plan's end (t + the approach's duration), then the pause
        if self._watched:  # feedback OFF: the approach is watched on the image (pipeline.sim.approach)
            self._next_look(t)

    def _next_look(self, t: float) -> None:
        # looks while the movement runs (the plan is the approach's until a stop); after it (nothing left to stop)
        # the first decision after its pause
        look = t + self.params.approach_look_s
        self._next = look if look < self._p_end else self._p_end + self._interval

    def _watch(self, t: float) -> None:
        """A look at the image during a watched approach: stop it if the seen force is well past the aim."""
        p = self.params
        self._next_look(t)
        d = float(self._hd[self._lookup(t - p.tau_visual_s - p.camera_latency_s)])
        if seen_over_aim(d, self._khat, self._n, self._target, p.approach_stop_excess):
            # a guarded move's stop: the equilibrium stays where it is now (a stop, not a submovement: no D) and
            # the next decision comes after the usual pause, as after any movement
            self._plan(t, 1e-3, self._plan_value(t))
            self._stage = _CONTROL
            self._next = t + self._interval

    def _decide(self, t: float) -> None:
        """One intermittent decision: perceive (delayed, noisy), then hold or start a submovement."""
        p = self.params
        self.decisions += 1
        self._stage = _CONTROL
        self._next = t + self._period
        # visual percept
        j = self._lookup(t - p.tau_visual_s - p.camera_latency_s)
        d = float(self._hd[j])
        if not (0.0 <= d <= 0.05):
            if d != d:
                return  # no usable image: wait for the next look
            d = 0.0 if d < 0.0 else 0.05
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
            felt = float(self._hf[self._lookup(t - p.tau_haptic_s)])
            if -10.0 <= felt <= 10.0:  # also rejects NaN
                sh = weber_sigma(p.sigma_haptic, felt)  # σ_h at the GENTLE display, 0.8 σ_h at FIRM's
                f_hap = inverse_scale(felt * math.exp(sh * self._randn()), self._fmax, self._fscale)
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
