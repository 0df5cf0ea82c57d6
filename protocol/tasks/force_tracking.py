"""Force tracking: follow a target force that moves over the trial -- a ramp, a sine or a sequence of steps.

Where force regulation (:mod:`protocol.tasks.force_regulation`) trains reaching and holding one force, tracking
trains and tests *dynamic* force control (issue 43; docs/tracking.md says what it measures, why, and the sources
of the simulated hand's parameters).  Definitions:

* **profile** -- the target over trial time, the protocol file's ``[task]`` table: it holds its first value for
  ``lead_in_s`` (time to reach the tissue), then moves for ``duration_s`` and the trial ends:

  - ``profile = "ramp"``: linear from ``from_n`` to ``to_n``;
  - ``profile = "sine"``: ``offset_n + amplitude_n·sin(2π·frequency_hz·t)`` (t from the lead-in's end);
  - ``profile = "steps"``: the forces ``levels_n``, each held ``duration_s / len(levels_n)``;

* **band** -- ``|F − F*(t)| ≤ band_n`` around the moving target (an absolute half-width: a relative one would
  vanish where a ramp starts at 0 N);
* **success** -- the trial reached the profile's end (a tracking trial always runs its profile; how well it
  tracked is its metrics): the rule completes at the first sample at or after ``lead_in_s + duration_s``;
* **metrics** -- tracking RMSE and Max AE against ``F*(t)`` over the error window, time in band, and over the
  moving part the lag (the cross-correlation's peak) and the gain (the regression slope):
  :mod:`protocol.metrics.definitions`.

Validated when the file is read (one line naming the field, the value and what is allowed): the profile within
the device's range (0 N to ``safety.f_max_n``), a sine no faster than :data:`MAX_FREQUENCY_HZ`, steps no shorter
than a hand can settle, and lead-in plus profile within the trial cap.  The trial's ``[[targets]]`` name its
condition as in every study (the label is the cue word, F* scales the axes); the profile says the force.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from pipeline.core.aim import TrialAim
from pipeline.settings.tomlfields import Fields
from protocol.tasks.base import Parameter, Task, TaskTables, Timing, TrialCondition, TrialScreen, listed
from protocol.tasks.window import TrialMetrics, capped, judged

__all__ = ["MAX_FREQUENCY_HZ", "METRIC_NAMES", "PROFILES", "ForceTracking", "ProfileEnd"]

#: The metrics the task produces (:mod:`protocol.metrics`): RMSE and Max AE against the moving target (its primary
#: measures), time in band, lag and gain (secondary: each tested with its own p).  Not the success rate: a tracking
#: trial always runs its profile (its outcome says whether it did), so a rate would be 1 in both modes.
METRIC_NAMES = ("rmse_n", "max_ae_n", "time_in_band_s", "lag_s", "gain")
#: The profiles a protocol may name.
PROFILES = ("ramp", "sine", "steps")
#: The fastest sine a hand can follow: voluntary force modulation fades above ~2 Hz (Neilson 1972; the tracking
#: hand's 2.5 Hz bandwidth, :mod:`pipeline.sim.tracking_hand`).
MAX_FREQUENCY_HZ = 2.0
#: The shortest step: a reaction time plus a corrective movement (science.md §4.2: 0.5–1.0 s).
MIN_STEP_S = 1.0
#: Knots per second of a sine told to the simulated participant (linear between them: < 0.3 % of the amplitude off
#: at 2 Hz).
_SINE_KNOTS_PER_S = 200


class ProfileEnd:
    """The streaming rule: the first sample at or after the profile's end (the trial always runs its profile)."""

    __slots__ = ("_end_ns", "completed_ns")

    def __init__(self, end_ns: int) -> None:
        self._end_ns = end_ns
        self.completed_ns: int | None = None

    def feed(self, t_ns: int, force_n: float) -> bool:
        if self.completed_ns is None and t_ns >= self._end_ns:
            self.completed_ns = t_ns
            return True
        return False


@dataclass(frozen=True, slots=True)
class ForceTracking(Task):
    """Follow the profile's target force within ±``band_n`` (module docstring: its fields are the file's)."""

    profile: str = "sine"
    duration_s: float = 8.0
    lead_in_s: float = 4.0
    band_n: float = 0.1
    from_n: float = 0.3
    to_n: float = 1.2
    offset_n: float = 0.8
    amplitude_n: float = 0.4
    frequency_hz: float = 0.25
    levels_n: tuple[float, ...] = (0.4, 1.0, 0.6, 1.2)

    kind: ClassVar[str] = "force_tracking"
    title: ClassVar[str] = "force tracking"
    metric_names: ClassVar[tuple[str, ...]] = METRIC_NAMES
    task_fields: ClassVar[frozenset[str]] = frozenset(
        {"profile", "duration_s", "lead_in_s", "band_n", "from_n", "to_n", "offset_n", "amplitude_n", "frequency_hz",
         "levels_n"})
    described: ClassVar[tuple[Parameter, ...]] = (
        Parameter("profile", "the target's profile over the trial: ramp, sine or steps", "", "profile", 0),
        Parameter("duration_s", "how long the target moves (after the lead-in)", "s", "duration (s)", 3),
        Parameter("lead_in_s", "how long the target holds its first value after the cue", "s", "lead-in (s)", 3),
        Parameter("band_n", "half-width of the band around the moving target", "N", "band (N)", 4),
        Parameter("from_n", "ramp: the target at its start", "N", "from (N)", 4),
        Parameter("to_n", "ramp: the target at its end", "N", "to (N)", 4),
        Parameter("offset_n", "sine: its mean", "N", "offset (N)", 4),
        Parameter("amplitude_n", "sine: its amplitude", "N", "amplitude (N)", 4),
        Parameter("frequency_hz", "sine: its frequency", "Hz", "frequency (Hz)", 4),
        Parameter("levels_n", "steps: the forces in order, separated by /", "N", "levels (N)", 0),
    )

    # -- its parameters ------------------------------------------------------------------------------------------
    @classmethod
    def from_tables(cls, f: Fields, task: Mapping[str, Any], trial: Mapping[str, Any]) -> ForceTracking:
        d = cls()
        profile = f.choice("task.profile", task.get("profile", d.profile), PROFILES)
        force = {k: f.number(f"task.{k}", task.get(k, getattr(d, k)), lo=0.0, hi=20.0, lo_open=False)
                 for k in ("from_n", "to_n", "offset_n", "amplitude_n")}
        levels = task.get("levels_n", list(d.levels_n))
        return cls(
            profile=profile,
            duration_s=f.number("task.duration_s", task.get("duration_s", d.duration_s), lo=0.5, hi=300.0),
            lead_in_s=f.number("task.lead_in_s", task.get("lead_in_s", d.lead_in_s), lo=0.0, hi=30.0,
                               lo_open=False),
            band_n=f.number("task.band_n", task.get("band_n", d.band_n), lo=0.0, hi=2.0),
            frequency_hz=f.number("task.frequency_hz", task.get("frequency_hz", d.frequency_hz), lo=0.0,
                                  hi=MAX_FREQUENCY_HZ, note=f"Hz (a hand cannot follow a force faster than about "
                                  f"{MAX_FREQUENCY_HZ:g} Hz)"),
            levels_n=tuple(f.list_of("task.levels_n", levels, lambda fld, v: f.number(fld, v, lo=0.0, hi=20.0,
                                                                                     lo_open=False),
                                     min_len=1, max_len=20, what="a list of 1 to 20 forces in N")),
            **force,
        )

    def tables(self) -> TaskTables:
        # every field, the other profiles' too (their defaults): one set of columns for every tracking session
        return {"profile": self.profile, "duration_s": self.duration_s, "lead_in_s": self.lead_in_s,
                "band_n": self.band_n, "from_n": self.from_n, "to_n": self.to_n, "offset_n": self.offset_n,
                "amplitude_n": self.amplitude_n, "frequency_hz": self.frequency_hz,
                "levels_n": list(self.levels_n)}, {}

    def parameters(self) -> dict[str, Any]:
        return {**self.tables()[0], "levels_n": "/".join(f"{v:g}" for v in self.levels_n)}  # a table's cell

    def check_timing(self, f: Fields, timing: Timing) -> None:
        """The profile within the device's range (0 to ``safety.f_max_n``), steps a hand can settle in, and the
        lead-in plus the profile within the trial cap (and a training trial's length)."""
        lo, hi = self.range_n()
        limit = timing.ramps.f_max_n
        field = {"ramp": "task.to_n", "sine": "task.amplitude_n", "steps": "task.levels_n"}[self.profile]
        if lo < 0.0 or hi > limit:
            raise f.fail(field, self.tables()[0][field.removeprefix("task.")],
                         f"the profile spans {lo:g}–{hi:g} N: it must stay within 0–{limit:g} N (safety.f_max_n, "
                         "the device's force limit)")
        if self.profile == "steps" and self.duration_s / len(self.levels_n) < MIN_STEP_S:
            raise f.fail("task.duration_s", self.duration_s, f"must give each of the {len(self.levels_n)} steps at "
                         f"least {MIN_STEP_S:g} s (a reaction time and a correction)")
        need = self.lead_in_s + self.duration_s
        for fld, cap in (("trial.max_trial_s", timing.max_trial_s),
                         ("training.seconds_per_target_per_mode", timing.training_s)):
            if cap < need:
                raise f.fail(fld, cap, f"must be at least task.lead_in_s + task.duration_s = {need:g} s (a "
                             "tracking trial runs its whole profile)")

    # -- its target and its rule ---------------------------------------------------------------------------------
    def range_n(self) -> tuple[float, float]:
        """The least and the largest target force of the profile, N."""
        if self.profile == "ramp":
            return min(self.from_n, self.to_n), max(self.from_n, self.to_n)
        if self.profile == "sine":
            return self.offset_n - self.amplitude_n, self.offset_n + self.amplitude_n
        return min(self.levels_n), max(self.levels_n)

    def profile_n(self, t_s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The target at trial times ``t_s`` (s since the cue), N: the first value through the lead-in, the last
        after the end."""
        x = np.clip(np.asarray(t_s, dtype=np.float64) - self.lead_in_s, 0.0, self.duration_s)
        if self.profile == "ramp":
            return self.from_n + (self.to_n - self.from_n) * x / self.duration_s
        if self.profile == "sine":
            return self.offset_n + self.amplitude_n * np.sin(2.0 * math.pi * self.frequency_hz * x)
        step = self.duration_s / len(self.levels_n)
        k = np.minimum((x / step).astype(np.int64), len(self.levels_n) - 1)
        return np.asarray(self.levels_n, dtype=np.float64)[k]

    def target_n(self, trial: TrialCondition, t_s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return self.profile_n(t_s)

    def end_ns(self) -> int:
        """The profile's end, ns since the cue: where a tracking trial completes."""
        return int(round((self.lead_in_s + self.duration_s) * 1e9))

    def rule(self, trial: TrialCondition) -> ProfileEnd:
        return ProfileEnd(self.end_ns())

    def judge(self, t_ns: npt.ArrayLike, force_n: npt.ArrayLike, trial: TrialCondition, *, max_trial_s: float,
              window: str = "cue", sample_period_s: float = 0.001) -> TrialMetrics:
        t, f = capped(t_ns, force_n, max_trial_s, window)
        reached = np.flatnonzero(t >= self.end_ns())
        done = int(reached[0]) if len(reached) else None
        target = self.profile_n(t / 1e9)  # judged keeps a prefix of t: the band's target is the prefix's

        def on_target(force: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
            return np.abs(force - target[:len(force)]) <= self.band_n

        return judged(t, f, done, target_n=lambda times: self.profile_n(times / 1e9), on_target=on_target,
                      max_trial_s=max_trial_s, window=window, sample_period_s=sample_period_s, metrics=self.metrics)

    # -- what it shows and tells ---------------------------------------------------------------------------------
    def cue_text(self, trial: TrialCondition) -> str:
        return f"{trial.target_label} track {self.profile_words()}"

    def profile_words(self) -> str:
        """The profile in a few words (``sine 0.8 ± 0.4 N at 0.25 Hz``)."""
        if self.profile == "ramp":
            return f"ramp {self.from_n:g}→{self.to_n:g} N over {self.duration_s:g} s"
        if self.profile == "sine":
            return f"sine {self.offset_n:g} ± {self.amplitude_n:g} N at {self.frequency_hz:g} Hz"
        return f"steps {'/'.join(f'{v:g}' for v in self.levels_n)} N, {self.duration_s / len(self.levels_n):g} s each"

    def screen(self, trial: TrialCondition) -> TrialScreen:
        return TrialScreen(
            cue_word=trial.target_label, band=self.band_edges,
            band_label=f"{trial.target_label}: track {self.profile_words()} ± {self.band_n:g} N",
            band_legend=f"target ± {self.band_n:g} N ({self.profile})",
            follow="Follow the target",
        )

    def band_edges(self, t_s: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """The band at trial times ``t_s`` (s since the cue), N: it moves with the profile."""
        f = self.profile_n(t_s)
        return f - self.band_n, f + self.band_n

    def aim(self, trial: TrialCondition, aid: bool) -> TrialAim:
        end = self.lead_in_s + self.duration_s
        if self.profile == "ramp":
            times = [0.0, self.lead_in_s, end] if self.lead_in_s > 0 else [0.0, end]
        elif self.profile == "sine":
            n = max(2, int(self.duration_s * _SINE_KNOTS_PER_S))
            times = [0.0, *(self.lead_in_s + self.duration_s * k / n for k in range(1 if self.lead_in_s == 0 else 0,
                                                                                 n + 1))]
        else:  # a step is two knots 1 ms apart (the knots are linear between them)
            step = self.duration_s / len(self.levels_n)
            edges = [self.lead_in_s + step * k for k in range(1, len(self.levels_n))]
            times = [0.0, *(e + d for e in edges for d in (-1e-3, 0.0)), end]
        forces = self.profile_n(np.asarray(times))
        knots = tuple((float(a), float(b)) for a, b in zip(times, forces, strict=True))
        return TrialAim(knots, trial.haptic_mode == "on", gauge=aid, practice=aid)

    # -- its words in the report ---------------------------------------------------------------------------------
    def rule_words(self) -> str:
        return f"track {self.profile_words()}, band ±{self.band_n:g} N"

    @classmethod
    def methods(cls, tasks: Sequence[Task], caps: Sequence[float]) -> str:
        mine = [t for t in tasks if isinstance(t, ForceTracking)]
        profiles = "; ".join(sorted({t.profile_words() for t in mine}))
        return (f"The target force follows a profile ({profiles}) after a lead-in of "
                f"{listed([t.lead_in_s for t in mine], ' s')} at its first value; a tracking trial runs the whole "
                f"profile (cap {listed(caps, ' s')}). RMSE and Max AE are taken against the moving target F*(t); a "
                f"sample is in the band when |F − F*(t)| ≤ {listed([t.band_n for t in mine], ' N')}; the lag is the "
                "peak of the cross-correlation between target and task force over the moving part (positive: the "
                "force follows), the gain the least-squares slope of the force on the target there.")
