"""The simulated participant's hand in a force-*tracking* trial: a target that moves over the trial.

:class:`pipeline.sim.participant.SimulatedParticipant` models force *regulation* (intermittent submovements towards
a force that does not move); when a trial's aim moves (:attr:`pipeline.core.aim.TrialAim.steady_n` is None) it hands
the trial to a :class:`TrackingHand`, which returns the arm's equilibrium every tick until the trial ends.  The
participant's own constants (:class:`pipeline.sim.participant_params.ParticipantParams`: its delays, percept noise
and stiffness belief, each sourced there) are used as drawn, so the same person regulates and tracks.

Model: continuous pursuit tracking (McRuer's crossover model: the human adapts the loop gain to the loop's delay)

* **feed-forward**: the target on the screen, seen with the visual delay ``τ_v + camera``, turned into the believed
  depth ``(F*/k̂)^{1/n}`` below the believed surface (the per-trial stiffness belief ``k̂`` and surface error are the
  regulation model's);
* **feedback**: every 10 ms a delayed, noisy force percept -- visual ``k̂·δⁿ`` (delay ``τ_v + camera``) and, with
  haptics ON, the felt force mapped back through the tanh law (delay ``τ_h``), combined with the regulation model's
  maximum-likelihood weights -- drives an integrator of the depth error ``δ̂(F*) − δ̂(F̂)``;
* **the crossover rule**: the integrator's gain is ``ω_c = φ / τ_fb`` with ``φ = 0.5`` rad (a phase margin of about
  60°: McRuer & Jex 1967, the crossover model's ``ω_c·τ_e`` of 0.4–0.8 rad for a pure-gain plant) and ``τ_fb`` the
  percept's delay (the weighted mean of the channels' delays).  With haptics OFF ``τ_fb`` ≈ 0.23–0.36 s (visual:
  ``τ_v`` 0.18–0.26 s plus the camera's 0.05–0.10 s); ON the felt force arrives after ``τ_h`` 0.10–0.14 s (the
  haptic loop is faster than the visuomotor one: science.md §4.1), so ``ω_c`` is higher and the stiffness belief's
  error -- which the visual percept cannot see, being judged through the same belief -- is corrected by the felt
  force;
* **the reflex** (haptics ON only): the force felt 60 ms ago (the long-latency stretch reflex: Matthews 1991;
  Pruszynski & Scott 2012) against the force meant then, corrected in proportion -- a fast loop closed around the
  hand's own low-pass, so the force follows its command sooner (a shorter lag) and at the felt, not the believed,
  size (a gain nearer 1).  Vision has no such loop: its percept is ``τ_v + camera`` old and judged through ``k̂``;
* **the hand's bandwidth**: the commanded equilibrium passes a first-order low-pass of 2.5 Hz (voluntary force
  modulation follows up to about 2–3 Hz and fades above: Neilson 1972; Sosnoff & Newell 2005), with additive motor
  noise of σ 0.1 mm per control step (the regulation model's ``motor_noise_abs_m``).

**Hence haptics ON lowers the error and shortens the lag**: the felt force is the true one (the error of the
stiffness belief, which vision cannot see, is corrected), its voluntary loop runs at a higher crossover, and the
reflex speeds the force's response to the command (the mechanism the tracking study checks: docs/tracking.md).

Safety: the output is clamped to the participant's safe range by the caller, and a non-finite percept is no look.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.core.aim import TrialAim
from pipeline.force.scaling import scale_magnitude
from pipeline.sim.hand import HandObservation
from pipeline.sim.participant_params import ParticipantParams
from pipeline.sim.percepts import HISTORY_TICKS, inverse_scale, newest_at

__all__ = ["CONTROL_S", "CROSSOVER_PHASE_RAD", "HAND_BANDWIDTH_HZ", "REFLEX_GAIN", "REFLEX_S", "TrackingHand"]

#: The control step: a percept and an integrator update every 10 ms (far shorter than any delay of the loop).
CONTROL_S = 0.01
#: ``ω_c·τ_fb``: the crossover model's phase budget (McRuer & Jex 1967: 0.4–0.8 rad), ≈ 60° of phase margin.
CROSSOVER_PHASE_RAD = 0.5
#: The hand's first-order bandwidth, Hz (voluntary force modulation follows to ~2–3 Hz: Neilson 1972).
HAND_BANDWIDTH_HZ = 2.5
#: The long-latency stretch reflex's delay, s: 50–80 ms (Matthews 1991; Pruszynski & Scott 2012), well under the
#: voluntary haptic reaction (τ_h 0.10–0.14 s) and the visuomotor delay (τ_v + camera 0.23–0.36 s).
REFLEX_S = 0.06
#: The reflex's proportional gain on the felt force's error (believed depth per believed depth).  Around the hand's
#: 2.5 Hz low-pass and the 60 ms delay alone a gain of 1 would keep a margin of about 2 (the phase reaches −180°
#: near 33 rad/s, where the low-pass passes 0.43); on the simulated rig the pipeline's filter, the rendering and the
#: arm add delay, and 1 oscillated: 0.4 is stable there (an assumption, chosen, not fitted to a result).
REFLEX_GAIN = 0.4
_HIST = HISTORY_TICKS  # ticks of observation history (≥ the longest delay, 0.36 s, at 1 kHz)
_MASK = _HIST - 1


class TrackingHand:
    """One tracking trial's hand: :meth:`equilibrium_y` every tick from the cue on (module docstring).

    Parameters
    ----------
    aim
        The trial's target over trial time (moving).
    params
        The participant's constants.
    rng
        The trial's own random stream (the participant's common random numbers).
    t0_s, y0_m
        The cue's time on the participant's clock and the equilibrium there (the hand starts where it is).
    stiffness, exponent, arm_k, motion_scale, f_max_n, f_scale_n
        The participant's tissue model (``k``, ``n``), its arm's stiffness, the motion scale and the haptic law.
    """

    def __init__(self, aim: TrialAim, params: ParticipantParams, rng: np.random.Generator, t0_s: float, y0_m: float,
                 *, stiffness: float, exponent: float, arm_k: float, motion_scale: float, f_max_n: float,
                 f_scale_n: float) -> None:
        p = self.params = params
        self.aim, self._rng, self._t0, self._s = aim, rng, t0_s, motion_scale
        self._k, self._inv_n, self._n = stiffness, 1.0 / exponent, exponent
        self._arm_k, self._fmax, self._fscale = arm_k, f_max_n, f_scale_n
        z = float(np.clip(rng.standard_normal(), -3.0, 3.0))
        self._khat = stiffness * p.stiffness_belief_median * math.exp(p.stiffness_belief_sigma * z)
        self._surface_err = p.surface_sigma_m * float(np.clip(rng.standard_normal(), -3.0, 3.0))
        self._start = t0_s + p.reaction_center_s + float(rng.uniform(-0.1, 0.1))
        self._tau_v = p.tau_visual_s + p.camera_latency_s
        self._haptic = aim.haptic_on
        # the feedback's delay and the crossover gain it allows (the percepts' ML weights: the regulation model's)
        var_v = p.sigma_visual ** 2 + p.stiffness_belief_sigma ** 2
        var_h = p.sigma_haptic ** 2 + p.sigma_haptic_model ** 2
        self._w_h = var_v / (var_v + var_h) if self._haptic else 0.0
        self.feedback_delay_s = self._w_h * p.tau_haptic_s + (1.0 - self._w_h) * self._tau_v
        self.crossover_rad_s = CROSSOVER_PHASE_RAD / self.feedback_delay_s
        self._alpha = 1.0 - math.exp(-2.0 * math.pi * HAND_BANDWIDTH_HZ * 1e-3)  # the low-pass per 1 ms tick
        self._surface: float | None = None  # believed surface, stylus coordinates (set at the reaction time)
        self._u = 0.0  # the integrator's depth correction, m
        self._cmd = self._y = self._y0 = y0_m
        self._next = self._start
        self._ht = np.full(_HIST, -math.inf)
        self._hf = np.zeros(_HIST)
        self._hd = np.zeros(_HIST)
        self._hi = 0

    def equilibrium_y(self, obs: HandObservation) -> float:
        """The arm's equilibrium this tick (m along the Touch's +y from the start pose; unclamped)."""
        t = obs.t_s
        i = self._hi = (self._hi + 1) & _MASK
        self._ht[i], self._hf[i], self._hd[i] = t, obs.felt_force_n, obs.indentation_m
        if t >= self._next:
            self._next = max(self._next + CONTROL_S, t)
            if self._surface is None:
                self._find_surface(obs)
            self._control(t)
        self._y += self._alpha * (self._cmd - self._y)
        return self._y

    def _find_surface(self, obs: HandObservation) -> None:
        gap = obs.gap_m if 0.0 <= obs.gap_m <= 0.1 else 0.015
        ind = obs.indentation_m if 0.0 <= obs.indentation_m <= 0.05 else 0.0
        y_st = obs.stylus_y_m if -0.1 <= obs.stylus_y_m <= 0.1 else self._y
        self._surface = y_st - (gap + self._surface_err) / self._s + ind / self._s

    def _depth(self, force_n: float) -> float:
        return (force_n / self._khat) ** self._inv_n if force_n > 0.0 else 0.0

    def _at(self, tq: float) -> int:
        """The newest history sample at or before ``tq`` (not before the cue)."""
        return newest_at(self._ht, self._hi, float(tq), float(self._t0))

    def _percept(self, t: float) -> float | None:
        """The force the participant perceives now (delayed, noisy), N; None: no usable look."""
        p, rng = self.params, self._rng
        d = float(self._hd[self._at(t - self._tau_v)])
        if not (0.0 <= d <= 0.05):
            return None
        f_hat: float = self._khat * d ** self._n * math.exp(p.sigma_visual * rng.standard_normal())
        if self._haptic:
            felt = float(self._hf[self._at(t - p.tau_haptic_s)])
            if -10.0 <= felt <= 10.0:
                f_hap = inverse_scale(felt * math.exp(p.sigma_haptic * rng.standard_normal()), self._fmax, self._fscale)
                f_hat = self._w_h * f_hap + (1.0 - self._w_h) * f_hat
        return f_hat

    def _control(self, t: float) -> None:
        if self._surface is None:
            return
        seen = self.aim.force_n(t - self._t0 - self._tau_v)  # the screen's target, seen with the visual delay
        x = (t - self._start) / self.params.approach_center_s
        f_hat = self._percept(t) if x >= 1.0 else None  # no correction before the approach has reached the tissue
        if f_hat is not None:
            err = self._depth(seen) - self._depth(f_hat)
            self._u += self.crossover_rad_s * CONTROL_S * err
        push = 0.0
        if self._haptic:  # the felt push-back the participant expects at the target, pre-compensated (regulation's)
            push = self.params.pushback_comp * scale_magnitude(seen, self._fmax, self._fscale) / self._arm_k
        if self._haptic and f_hat is not None:  # the reflex: the felt force against the force meant then
            push += self._reflex_m(t)
        noise = self.params.motor_noise_abs_m * self._rng.standard_normal()
        cmd = self._surface - (self._depth(seen) + self._u) / self._s - push + noise
        # the first reach to the tissue is a feed-forward minimum-jerk approach, as in regulation (1.1–1.7 s)
        blend = 1.0 if x >= 1.0 else x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)
        self._cmd = self._y0 + blend * (cmd - self._y0)

    def _reflex_m(self, t: float) -> float:
        """The long-latency reflex's correction, m of believed depth: the force felt ``REFLEX_S`` ago against the
        force meant then (the target seen then), in proportion (:data:`REFLEX_GAIN`)."""
        felt = float(self._hf[self._at(t - REFLEX_S)])
        if not -10.0 <= felt <= 10.0:
            return 0.0
        f_felt = inverse_scale(felt, self._fmax, self._fscale)
        meant = self.aim.force_n(t - REFLEX_S - self._t0 - self._tau_v)
        return REFLEX_GAIN * (self._depth(f_felt) - self._depth(meant)) / self._s

    def value(self) -> float:
        """The equilibrium last returned (where a retraction starts)."""
        return self._y
