"""End-to-end latency: how long a force at the instrument's tip takes to reach the participant's hand, stage by stage,
and how long the hand's motion takes to reach the tip.

Two paths make the loop a participant closes with the tissue (science.md §8):

* **the force path**, tip → hand: the F/T sensor samples and sends; the 1 kHz loop takes the newest sample at its
  next tick and computes; the moving average delays it by about half its window; the safety stage lets the
  rendered force change by at most 50 N/s (a step of force takes its size / 50 N/s); the haptic device's servo
  renders the command at its next servo tick;
* **the motion path**, hand → tip: the robot follows the stylus -- its controller's cycle (8 ms on a CB3), its
  tracking, and with app-side teleoperation the ``servoL`` look-ahead, which smooths the targets by about its own
  length (Universal Robots' client library #86 measured ~34 ms of lag at 0.03 s, 4--6 ms without the servo).

:func:`simulated_stages` measures every stage the simulated rig has, on a twin of it with the pipeline's settings:
a step of tip force (and a step of the stylus), the virtual clock, each stage's output timed where it first reaches
half its step.  :func:`live_stages` adds what only the running loop knows: the age of the F/T sample at the tick
that uses it and the tick's own computing, from the loop's records.  :func:`robot_stage` states the real robot's
share from the hardware file.  :class:`Latency` holds a breakdown: its totals, its lines, and the plain data a
session stores (``config_json``'s ``latency``, real clock only).  How to measure the real rig end to end -- the
loopback fakes' timestamps, then a tap test on hardware -- is docs/hardware-setup.md, "End-to-end latency".
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.force.config import FrameworkConfig

__all__ = ["STEP_N", "Latency", "Stage", "live_stages", "robot_stage", "simulated_stages"]

#: The step of tip force measured, N: the study's scale (its targets are 0.6 and 1.2 N).  The slew limit makes the
#: safety stage's share grow with the step (a step of F renders 3·tanh(F/7) N, at 50 N/s).
STEP_N = 1.0
#: The step of the stylus measured on the motion path, m (a firm press moves the stylus a few millimetres).
STYLUS_STEP_M = 0.003
_SETTLE_TICKS = 800  # feedback ramps in over 0.5 s; the twin settles before the step
_STEP_TICKS = 400


@dataclass(frozen=True, slots=True)
class Stage:
    """One stage of a path: ``path`` ``"force"`` (tip → hand) or ``"motion"`` (hand → tip), what it is, its delay in
    ms (NaN: not measured here), and where the number comes from."""

    path: str
    name: str
    ms: float
    source: str


@dataclass(frozen=True, slots=True)
class Latency:
    """A latency breakdown: the stages of both paths, and the step of tip force it was measured with."""

    stages: tuple[Stage, ...]
    step_n: float = STEP_N

    def path_ms(self, path: str) -> float:
        """A path's total, ms: the sum of its measured stages (NaN when none is)."""
        vals = [s.ms for s in self.stages if s.path == path and math.isfinite(s.ms)]
        return float(sum(vals)) if vals else math.nan

    @property
    def force_ms(self) -> float:
        """Tip → hand, ms."""
        return self.path_ms("force")

    @property
    def motion_ms(self) -> float:
        """Hand → tip, ms."""
        return self.path_ms("motion")

    @property
    def total_ms(self) -> float:
        """The round trip a press closes: hand → tip → hand, ms (the force path alone when the motion path is not
        measured)."""
        m = self.motion_ms
        return self.force_ms + (m if math.isfinite(m) else 0.0)

    def summary(self) -> str:
        """One line: both paths and the round trip."""
        motion = f"{self.motion_ms:.1f} ms" if math.isfinite(self.motion_ms) else "not measured"
        return (f"tip → hand {self.force_ms:.1f} ms, hand → tip {motion}, round trip {self.total_ms:.1f} ms "
                f"(a {self.step_n:g} N step of tip force)")

    def lines(self) -> list[str]:
        """One line per stage, each path's first."""
        out = []
        for path, what in (("force", "tip → hand"), ("motion", "hand → tip")):
            for s in self.stages:
                if s.path == path:
                    ms = f"{s.ms:5.1f} ms" if math.isfinite(s.ms) else "    – ms"
                    out.append(f"{what}: {ms}  {s.name} [{s.source}]")
        return out

    def stages_text(self, path: str) -> str:
        """A path's stages in one line: ``moving average (10 samples) 4.0 ms, …`` (``–`` where not measured)."""
        return ", ".join(f"{s.name} {s.ms:.1f} ms" if math.isfinite(s.ms) else f"{s.name} –"
                         for s in self.stages if s.path == path)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON): the totals and every stage."""
        def num(v: float) -> float | None:
            return round(v, 3) if math.isfinite(v) else None

        return {"force_ms": num(self.force_ms), "motion_ms": num(self.motion_ms), "total_ms": num(self.total_ms),
                "step_n": self.step_n,
                "stages": [{"path": s.path, "name": s.name, "ms": num(s.ms), "source": s.source} for s in self.stages]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Latency:
        """Back from :meth:`to_dict`."""
        return cls(tuple(Stage(s["path"], s["name"], math.nan if s["ms"] is None else float(s["ms"]), s["source"])
                         for s in d.get("stages", ())), float(d.get("step_n", STEP_N)))


def _half_step(t_ms: np.ndarray, x: np.ndarray, start: int) -> float:
    """When ``x`` first reaches half its step (from its value before ``start`` to its last), ms; NaN if never."""
    before, after = float(x[start - 1]), float(x[-1])
    if abs(after - before) < 1e-9:
        return math.nan
    frac = (x[start:] - before) / (after - before)
    hit = np.flatnonzero(frac >= 0.5)
    return float(t_ms[start + hit[0]]) if len(hit) else math.nan


def _twin(framework: FrameworkConfig, sim: Any) -> Any:
    """A weightless, noise-free, bias-free twin of the simulated rig with the pipeline's settings, feedback on,
    the stylus held still: the stages' timing without what calibration and noise add (which delays nothing)."""
    from pipeline.assembly.engine import EngineConfig, build_sim_engine
    from pipeline.sim.rig import SimRigConfig
    from pipeline.sim.sensor import SensorParams

    base = sim if sim is not None else SimRigConfig()
    quiet = SensorParams(mass_kg=0.0, bias_force_n=(0.0, 0.0, 0.0), bias_torque_nm=(0.0, 0.0, 0.0),
                         drift_force_n=(0.0, 0.0, 0.0), random_walk_n_per_sqrt_s=0.0, noise_force_n=(0.0, 0.0, 0.0),
                         noise_torque_nm=(0.0, 0.0, 0.0))
    cfg = EngineConfig(sim=dataclasses.replace(base, sensor=quiet, mount_error_deg=0.0), framework=framework,
                       clock="virtual", calibrate=False, driver="hold", haptics_on=True, refine_bias=False,
                       ring_seconds=5.0)
    return build_sim_engine(cfg)


def _force_path(framework: FrameworkConfig, sim: Any, step_n: float) -> list[Stage]:
    eng = _twin(framework, sim)
    loop, rig = eng.loop, eng.rig
    loop.run_ticks(_SETTLE_TICKS)
    cursor = eng.ring.write_count
    applied: list[float] = []
    n = _SETTLE_TICKS // 4
    for k in range(n + _STEP_TICKS):
        if k == n:
            rig.push_base_n = (0.0, 0.0, step_n)  # the tissue's push on the tip, base frame
        loop.run_ticks(1)
        applied.append(math.hypot(*rig.haptic.applied_force_n))
    rows = eng.ring.read_since(cursor).rows
    t_ms = (rows["t_ns"] - rows["t_ns"][0]) * 1e-6

    def mag(prefix: str) -> np.ndarray:
        x, y, z = (np.asarray(rows[f"{prefix}_f{a}"], dtype=np.float64) for a in "xyz")
        return np.asarray(np.sqrt(x * x + y * y + z * z))

    times = [_half_step(t_ms, x, n) for x in (mag("true"), mag("raw"), mag("filt"), mag("render"),
                                              np.asarray(applied))]
    t_true, t_raw, t_filt, t_render, t_device = times
    rig.close()
    source = "measured on the simulated rig"
    safety = framework.safety
    return [
        Stage("force", "F/T sensor: sampling and transport", t_raw - t_true, source),
        Stage("force", f"moving average ({framework.filter_window} samples)", t_filt - t_raw, source),
        # one stage: the rotations and the tanh law act within the tick, but the law's curve moves a step's half-way
        # point, which only the stage after it (the slew limit) can be timed against
        Stage("force", f"rotations, tanh scaling and the safety stage's slew limit ({safety.slew_n_per_s:g} N/s)",
              t_render - t_filt, source),
        Stage("force", "haptic device: its servo renders the command", t_device - t_render, source),
    ]


def _motion_path(framework: FrameworkConfig, sim: Any) -> list[Stage]:
    from pipeline.sim.hand import HoldStill

    eng = _twin(framework, sim)
    loop, rig = eng.loop, eng.rig
    loop.run_ticks(_SETTLE_TICKS // 4)
    cursor = eng.ring.write_count
    n = _SETTLE_TICKS // 4
    loop.run_ticks(n)
    rig.set_driver(HoldStill(STYLUS_STEP_M))
    loop.run_ticks(_STEP_TICKS)
    rows = eng.ring.read_since(cursor).rows
    rig.close()
    t_ms = (rows["t_ns"] - rows["t_ns"][0]) * 1e-6
    stylus = np.sqrt(rows["stylus_x_m"] ** 2 + rows["stylus_y_m"] ** 2 + rows["stylus_z_m"] ** 2)
    t_stylus = _half_step(t_ms, stylus, n)
    t_tip = _half_step(t_ms, np.asarray(rows["tip_z_m"]), n)
    p = eng.rig.config.robot_params
    return [Stage("motion", f"robot: its {1e3 / p.controller_rate_hz:g} ms controller cycle and "
                            f"{1e3 * p.tracking_lag_s:g} ms tracking lag (the simulated UR3's)",
                  t_tip - t_stylus, "measured on the simulated rig")]


def simulated_stages(framework: FrameworkConfig | None = None, sim: Any = None, *,
                     step_n: float = STEP_N) -> tuple[Stage, ...]:
    """Every stage of both paths the simulated rig has, measured on a twin of it (see the module's docstring).

    ``framework``: the pipeline's settings (None: the paper's); ``sim``: the simulated rig's configuration (a
    :class:`pipeline.sim.rig.SimRigConfig`; None: its defaults).
    """
    fw = framework if framework is not None else FrameworkConfig()
    return (*_force_path(fw, sim, step_n), *_motion_path(fw, sim))


def live_stages(rows: np.ndarray) -> tuple[Stage, ...]:
    """What the running loop adds, from its records (real clock): the F/T sample's age at the tick that uses it,
    and the tick's computing from the sample to the command (medians)."""
    if not len(rows):
        return ()
    age_ms = np.asarray(rows["sensor_age_ns"], dtype=np.float64) * 1e-6
    compute_ms = (np.asarray(rows["latency_ns"], dtype=np.float64) - rows["sensor_age_ns"]) * 1e-6
    return (Stage("force", "loop: the F/T sample waits for the next tick", float(np.median(age_ms)),
                  f"median of the loop's last {len(rows)} records"),
            Stage("force", "loop: the tick computes the command", float(np.median(compute_ms)),
                  f"median of the loop's last {len(rows)} records"))


def robot_stage(mode: str, lookahead_s: float | None, controller_rate_hz: float) -> Stage:
    """The real robot's share of the motion path, from the hardware file.

    ``"observe"`` (the paper's set-up: the robot runs its own teleoperation program) is not ours to time here: a tap
    test measures it.  ``"teleop"``: the ``servoL`` look-ahead (its lag is about its length: #86 measured ~34 ms at
    0.03 s) plus one controller cycle.
    """
    cycle_ms = 1e3 / controller_rate_hz
    if mode != "teleop" or lookahead_s is None:
        return Stage("motion", "robot: its own program follows the stylus (observe mode)", math.nan,
                     "not measured by the app: a tap test on the rig (docs/hardware-setup.md)")
    return Stage("motion", f"robot: servoL look-ahead {lookahead_s:g} s and its {cycle_ms:g} ms controller cycle",
                 1e3 * lookahead_s + cycle_ms, "the hardware file's look-ahead (UR client library #86: lag ≈ "
                                               "look-ahead)")
