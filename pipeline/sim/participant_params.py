"""Who the simulated participants are: their constants, the population they are drawn from, the calibration.

:class:`ParticipantParams` holds one participant's constants, drawn once from
the participant's seed (:meth:`ParticipantParams.draw`); the model that uses
them is :class:`pipeline.sim.participant.SimulatedParticipant`.

Parameters
----------
Drawn per participant (:data:`PARAM_RANGES`, uniform unless stated):

=======================  ===================  =========================================
parameter                range                source
=======================  ===================  =========================================
τ_v (visual)             0.18–0.26 s          science.md §4.1
camera latency           0.05–0.10 s          §4.1 ("extra visual-pipeline latency")
τ_h (haptic)             0.10–0.14 s          §4.1
reaction time            centre 0.6–0.9 s,    §4.2 rt0 ~ U(0.5, 1.0) (split into a
                         ±0.1 s per trial     participant and a trial part)
approach duration        centre 0.6–0.8 s,    §4.2 (0.5–0.9 s)
                         ±0.1 s per trial
D (submovement)          0.20–0.35 s          §4.2
T_int                    0.15–0.35 s          §4.2 (× 2.0 OFF, see deviations)
G (gain)                 0.5–0.9              §4.2
drift                    0.03–0.07 mm/√s      §4.2 (0.05 × U(0.6, 1.4))
b OFF / b ON             LogN(1, 0.15/0.05),  §4.2, truncated at ±2.5σ
                         ±2.5σ
σ_h (GENTLE display)     0.10–0.15            §4.1 JND 10–15 % (8–12 % at FIRM)
c_pb (push-back comp.)   0.3–0.9              [A] new, see deviations
search step              1–2 mm               [A] new, see deviations
=======================  ===================  =========================================

Fixed: k̂/k median 0.80, σ_k 0.22 (per-trial draw truncated at ±3σ); σ_v 0.06;
σ_h,model 0.13; σ_mem 0.10 OFF / 0.13 ON; surface-depth error σ 3 mm (±3σ);
OFF interval factor 2.0; motor noise 0.15 (relative) + 0.1 mm; hold band 5 %;
contact thresholds 1 mm / 0.05 N; gauge noise 0.03; retraction 0.4 s.

Deviations from science.md §4.2, and why:

1. **Stiffness-belief median 0.85 → 0.80.** Raises OFF over-pressing (OFF RMSE),
   bringing the RMSE change from −24 % to −31 % (paper −36 %); 1/0.80 = +25 %
   force is the novice excess of Golahmadi 2021 (+22.7 %, §4.1).  Lower
   medians (0.75) reach −32 % but drop OFF success to 0.20.
2. **OFF decision-interval factor 1.5 → 2.0** (§4.2 tuning knob): slower visual
   checking lengthens OFF corrections; TCT and RMSE effects grow a little.
3. **Surface-depth error σ 2.5 → 3 mm** (§3: "σ ≈ 2–3 mm"): raises both Max AE
   values toward the paper's (OFF 1.65 → 1.9 N, ON 1.14 → 1.24 N).
4. **σ_h per participant and force level** (0.10–0.15 at GENTLE, ×0.8 at FIRM)
   instead of a fixed 0.13: §4.1's JND ranges; a fixed 0.13 made ON holds
   noisier than OFF's and gave no TCT benefit (−3 %).
5. **The start gap is the rig's** (15 mm, not U(12, 25) mm); it is seen
   through ``obs.gap_m`` with the σ 3 mm depth error.
6. **Camera latency 50–100 ms** added to τ_v (§4.1).
7. **Secant step**: the amplitude uses the inverse model ``δ̂(F*) − δ̂(F̂)``
   (``(F*−F̂)/k̂'`` with k̂' the believed *secant* stiffness) instead of the local
   tangent stiffness, which is 0 at F̂ = 0 and overshoots badly from below on
   the convex Hunt–Crossley curve.
8. **Push-back compensation c_pb** (new): with feedback the arm is pushed back
   by f_H/K_a (0.5 mm at GENTLE, 1 mm at FIRM) — trained participants partly
   expect it.  Insensitive: c_pb = 0.2 for everyone changed no result beyond noise.
9. **Search step** (new): §4.2 does not say what happens when the approach ends
   above the surface (k̂' = 0 there); the participant steps down 1–2 mm per decision.
10. Lognormals are truncated (±2.5σ for participant constants, ±3σ per trial)
    so every drawn value has a documented range; drift runs only in trials
    (the start pose is exactly y_c = 0 between trials).

Calibration (``python -m bench.participant_calibration --studies 10 --jobs 2``;
real rig + loop + :class:`protocol.trial.TrialMachine` + :mod:`protocol.metrics`,
the paper's random 20-trial schedule; 10 studies × 10 participants, seeds
0–9; per participant × mode as science.md §6; mean ± SD [min–max] over the
10 studies; Wilcoxon signed-rank on the 10 paired differences):

=====================  ============  ============  =================  ===================  ====================
metric                 sim OFF       sim ON        change             paper                p < 0.05 (median p)
=====================  ============  ============  =================  ===================  ====================
success                0.267 ±0.051  0.540 ±0.039  ×2.09 ±0.45        0.27 → 0.54 (×2.0)   7/10 studies (0.018)
                       [0.20–0.36]   [0.48–0.61]   [×1.44–×2.67]
RMSE (N)               0.797 ±0.059  0.544 ±0.020  −31.4 ±6.1 %       1.35 → 0.86 (−36 %)  10/10 (0.003)
                       [0.69–0.87]   [0.51–0.58]   [−38.1 – −21.5 %]
Max AE (N)             1.94 ±0.17    1.24 ±0.07    −35.5 ±8.1 %       2.12 → 1.46 (−31 %)  10/10 (0.015)
                       [1.63–2.17]   [1.11–1.35]   [−43.5 – −20.3 %]
TCT (s), successes     6.83 ±0.38    5.70 ±0.43    −16.3 ±7.6 %       −16 %                4/10 (0.24)
                       [6.38–7.38]   [5.02–6.63]   [−29.6 – −5.9 %]
TCT (s), fails = 12 s  10.6 ±0.26    8.60 ±0.32    −18.9 ±3.7 %       (−16 %?)             9/10 (0.005)
success GENTLE         0.238 ±0.060  0.506 ±0.062  ×2.25                                   7/10 (0.025)
success FIRM           0.296 ±0.064  0.574 ±0.065  ×2.03                                   4/10 (0.068)
=====================  ============  ============  =================  ===================  ====================

Every effect has the paper's direction in every one of the 10 studies
(success up, RMSE, Max AE and TCT down with feedback).

Remaining gaps:

* **Absolute RMSE is ~60 % of the paper's** (0.80/0.54 vs 1.35/0.86 N) and the
  RMSE change is −31 % rather than −36 %.  With the metric's cue window, ON's
  quick successes keep their pre-contact phase (F = 0 for ~1.4 s) as a large
  share of a short window (ON successes have a *higher* RMSE than ON failures),
  which caps the achievable reduction.  The paper's 1.35 N OFF would need failed
  OFF trials ~1.5 N off target for most of 12 s (e.g. GENTLE held at ~2 N),
  which this model does not produce without also destroying OFF success;
  lowering the stiffness-belief median trades OFF success for RMSE.
* **Max AE change is −36 % (paper −31 %)** and ON Max AE 1.24 N is below 1.46 N:
  the arm's physical push-back in ON (the Wagner–Howe mechanism) limits ON
  overshoot strongly.  Studies range −20 % to −44 %.
* **TCT over successful trials**: mean −16 % as in the paper, but significant in
  only 4/10 studies (OFF participants have ~2.7 successes each, some none, so
  the per-participant means are noisy and pairs drop out).  Selection bias
  (only OFF's well-aligned trials succeed) is still visible in the spread
  (−6 % to −30 %).  With failures counted as 12 s the change is −19 %,
  significant in 9/10 studies; note that the paper's −16 % is also what
  27 %→54 % success gives for the mean trial duration, so the paper may have
  averaged TCT over all trials.
* **Success significance** 7/10 studies (paper: significant); FIRM alone 4/10.
* GENTLE is harder than FIRM in both modes (the absolute band is half as wide);
  the paper does not report the per-target split numerically.
* Study-to-study spread is large for a 10-participant study (OFF success
  0.20–0.36): any single simulated study can differ from the paper by more than
  the means above.

Wall time: one 10-participant study (~2.4 M loop ticks) takes ≈ 90 s in one
process on the 2-vCPU VM (90.6 s for study 3; ≈ 50 s per study with
``--jobs 2``, identical results); rig + loop + trial bookkeeping cost ≈ 37 µs
per tick there, the participant < 1 µs of it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = ["MODEL_FIT", "MODEL_VERSION", "PARAM_RANGES", "ParticipantParams"]

#: The participant model's version: changes whenever a parameter, range or behaviour changes what a simulated
#: study gives (a sweep's or a simulated study's results name it, so a prediction can be traced to its model).
MODEL_VERSION = "1"
#: What the fitted parameters were fitted to (one line; the calibration table is in this module's docstring).
MODEL_FIT = ("hand-tuned on 10 simulated 10-participant studies (seeds 0-9) to the paper's ratios of success, "
             "RMSE and Max AE (absolute RMSE ~60 % of the paper's)")


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
    stiffness_belief_median: float = 0.80  # k̂/k per trial ~ LogN(median, σ)
    stiffness_belief_sigma: float = 0.22
    sigma_visual: float = 0.06  # per-look log noise of the visual percept
    sigma_haptic_model: float = 0.13  # systematic part of the haptic percept's uncertainty (ML weight)
    sigma_gauge: float = 0.03  # per-look log noise of reading a live force gauge (training)
    sigma_mem_off: float = 0.10  # per-trial memory noise of the target, OFF
    sigma_mem_on: float = 0.13  # per-trial memory noise of the target, ON
    surface_sigma_m: float = 0.003  # per-trial error of the believed surface depth
    off_interval_factor: float = 2.0  # visual checking is slower than feeling
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
