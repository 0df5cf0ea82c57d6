"""Force tracking: follow a target force that moves over the trial -- a ramp, a sine or a sequence of steps.

Where force regulation (:mod:`protocol.tasks.force_regulation`) trains reaching and holding one force, tracking
trains and tests *dynamic* force control (issue 43; docs/tracking.md says what it measures, why, and the sources
of the simulated hand's parameters).  Definitions:

* **profile** -- the target over trial time, the protocol file's ``[task]`` table: it holds its first value for
  ``lead_in_s`` (time to reach the tissue), then moves for ``duration_s`` and the trial ends:

  - ``profile = "ramp"``: linear from ``from_n`` to ``to_n``;
  - ``profile = "sine"``: ``offset_n + amplitude_n·sin(2π·frequency_hz·t)`` (t from the lead-in's end);
  - ``profile = "steps"``: the forces ``levels_n``, each held ``duration_s / len(levels_n)``;

* **profiles by target** -- a ``[task.targets.LABEL]`` table changes the profile's fields for the trials of one
  ``[[targets]]`` label (``frequency_hz = 0.5`` for a FAST target beside a SLOW one): the protocol's profiles, which
  the report's trade of tracking error against target speed spans;
* **band** -- ``|F − F*(t)| ≤ band_n`` around the moving target (an absolute half-width: a relative one would
  vanish where a ramp starts at 0 N);
* **success** -- the trial reached the profile's end (a tracking trial always runs its profile; how well it
  tracked is its metrics): the rule completes at the first sample at or after ``lead_in_s + duration_s``;
* **display** -- what the participant screen shows of the target: ``"present"`` (the band where the target is now,
  moving; the default), ``"trace_ahead"`` (that, and the target's course over the next ``ahead_s`` seconds drawn
  above it, as a road seen ahead) or ``"word"`` (the cue word only: the target is felt, not seen);
* **metrics** -- tracking RMSE and Max AE against ``F*(t)`` over the error window, time in band, and over the
  moving part the lag (the cross-correlation's peak) and the gain (the regression slope):
  :mod:`protocol.metrics.definitions`.

Validated when the file is read (one line naming the field, the value and what is allowed): the profile within
the device's range (0 N to ``safety.f_max_n``), a sine no faster than :data:`MAX_FREQUENCY_HZ`, steps no shorter
than a hand can settle, and lead-in plus profile within the trial cap.  The trial's ``[[targets]]`` name its
condition as in every study (the label is the cue word, F* scales the axes); the profile says the force.
"""

from __future__ import annotations

import dataclasses
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

__all__ = ["DISPLAYS", "MAX_FREQUENCY_HZ", "METRIC_NAMES", "PROFILES", "ForceTracking", "ProfileEnd"]

#: The metrics the task produces (:mod:`protocol.metrics`): RMSE and Max AE against the moving target (its primary
#: measures), time in band, lag and gain (secondary: each tested with its own p).  Not the success rate: a tracking
#: trial always runs its profile (its outcome says whether it did), so a rate would be 1 in both modes.
METRIC_NAMES = ("rmse_n", "max_ae_n", "time_in_band_s", "lag_s", "gain")
#: The profiles a protocol may name.
PROFILES = ("ramp", "sine", "steps")
#: The fastest sine a hand can follow: voluntary force modulation fades above ~2 Hz (Neilson 1972; the tracking
#: hand's 2.5 Hz bandwidth, :mod:`pipeline.sim.tracking_hand`).
MAX_FREQUENCY_HZ = 2.0
#: What the participant screen may show of the target (``[task] display``).
DISPLAYS = ("present", "trace_ahead", "word")
#: The shortest step: a reaction time plus a corrective movement (science.md §4.2: 0.5–1.0 s).
MIN_STEP_S = 1.0
#: The fields of a profile, which a ``[task.targets.LABEL]`` table may change for one target's trials.
PROFILE_FIELDS = ("profile", "duration_s", "lead_in_s", "band_n", "from_n", "to_n", "offset_n", "amplitude_n",
                  "frequency_hz", "levels_n")
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
    #: A target's own profile fields, by target label (``[task.targets.LABEL]``; a field not named there: this one's).
    targets: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    #: What the participant screen shows of the target (:data:`DISPLAYS`), and how far ahead a trace reaches, s.
    display: str = "present"
    ahead_s: float = 2.0

    kind: ClassVar[str] = "force_tracking"
    title: ClassVar[str] = "force tracking"
    metric_names: ClassVar[tuple[str, ...]] = METRIC_NAMES
    task_fields: ClassVar[frozenset[str]] = frozenset({*PROFILE_FIELDS, "targets", "display", "ahead_s"})
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
        Parameter("profiles", "each target's profile, where a [task.targets.LABEL] table gives it one of its own "
                  "(LABEL: profile; ...); empty: every target tracks the profile above", "", "profiles by target", 0),
    )

    # -- its parameters ------------------------------------------------------------------------------------------
    @classmethod
    def from_tables(cls, f: Fields, task: Mapping[str, Any], trial: Mapping[str, Any]) -> ForceTracking:
        base = cls._profile(f, task, lambda k: f"task.{k}")
        own = task.get("targets", {})
        if not isinstance(own, dict):
            raise f.fail("task.targets", own, "must be a table of [task.targets.LABEL] tables")
        targets = []
        for label, table in own.items():
            where = f"task.targets.{label}"
            f.table(where, table, set(PROFILE_FIELDS))
            variant = cls._profile(f, {**task, **table}, lambda k, t=table, w=where: f"{w}.{k}" if k in t else
                                   f"task.{k}")
            targets.append((str(label), tuple((k, getattr(variant, k)) for k in PROFILE_FIELDS if k in table)))
        display = f.choice("task.display", task.get("display", base.display), DISPLAYS)
        ahead = f.number("task.ahead_s", task.get("ahead_s", base.ahead_s), lo=0.5, hi=10.0, lo_open=False,
                         note="s (the trace ahead: a glance of 0.5-10 s of the target's course)")
        if "ahead_s" in task and display != "trace_ahead":
            raise f.fail("task.ahead_s", task["ahead_s"], f"is read only with task.display = 'trace_ahead' (it is "
                         f"{display!r})")
        return dataclasses.replace(base, targets=tuple(targets), display=display, ahead_s=ahead)

    @classmethod
    def _profile(cls, f: Fields, task: Mapping[str, Any], name: Any) -> ForceTracking:
        """A profile from a table's fields (``name(key)``: the field's name in a refusal)."""
        d = cls()
        profile = f.choice(name("profile"), task.get("profile", d.profile), PROFILES)
        force: dict[str, Any] = {k: f.number(name(k), task.get(k, getattr(d, k)), lo=0.0, hi=20.0, lo_open=False)
                                 for k in ("from_n", "to_n", "offset_n", "amplitude_n")}
        levels = task.get("levels_n", list(d.levels_n))
        return cls(
            profile=profile,
            duration_s=f.number(name("duration_s"), task.get("duration_s", d.duration_s), lo=0.5, hi=300.0),
            lead_in_s=f.number(name("lead_in_s"), task.get("lead_in_s", d.lead_in_s), lo=0.0, hi=30.0,
                               lo_open=False),
            band_n=f.number(name("band_n"), task.get("band_n", d.band_n), lo=0.0, hi=2.0),
            frequency_hz=f.number(name("frequency_hz"), task.get("frequency_hz", d.frequency_hz), lo=0.0,
                                  hi=MAX_FREQUENCY_HZ, note=f"Hz (a hand cannot follow a force faster than about "
                                  f"{MAX_FREQUENCY_HZ:g} Hz)"),
            levels_n=tuple(f.list_of(name("levels_n"), levels, lambda fld, v: f.number(fld, v, lo=0.0, hi=20.0,
                                                                                      lo_open=False),
                                     min_len=1, max_len=20, what="a list of 1 to 20 forces in N")),
            **force,
        )

    def tables(self) -> TaskTables:
        # every field, the other profiles' too (their defaults): one set of columns for every tracking session
        own: dict[str, Any] = {"profile": self.profile, "duration_s": self.duration_s, "lead_in_s": self.lead_in_s,
                               "band_n": self.band_n, "from_n": self.from_n, "to_n": self.to_n,
                               "offset_n": self.offset_n, "amplitude_n": self.amplitude_n,
                               "frequency_hz": self.frequency_hz, "levels_n": list(self.levels_n)}
        if self.display != "present":  # (only where the file sets it: an earlier protocol stores what it stored)
            own["display"] = self.display
            if self.display == "trace_ahead":
                own["ahead_s"] = self.ahead_s
        if self.targets:  # (only where the file has them: a protocol of one profile stores what it always stored)
            own["targets"] = {label: {k: list(v) if isinstance(v, tuple) else v for k, v in fields}
                              for label, fields in self.targets}
        return own, {}

    def parameters(self) -> dict[str, Any]:
        own = {k: v for k, v in self.tables()[0].items() if k not in ("targets", "display", "ahead_s")}
        profiles = "; ".join(f"{label}: {self.of_target(label).profile_words()}" for label, _ in self.targets)
        return {**own, "levels_n": "/".join(f"{v:g}" for v in self.levels_n), "profiles": profiles}  # table cells

    def of_target(self, label: str) -> ForceTracking:
        """The profile a target's trials track: this one with the target's own fields (``[task.targets.LABEL]``)."""
        fields = dict(self.targets).get(label)
        return self if fields is None else dataclasses.replace(self, targets=(), **dict(fields))

    def for_trial(self, trial: TrialCondition) -> ForceTracking:
        """The profile a trial tracks (its target's, :meth:`of_target`)."""
        return self.of_target(trial.target_label)

    def profiles(self) -> tuple[ForceTracking, ...]:
        """Every profile of the protocol: this one and each target's own."""
        return (self, *(self.of_target(label) for label, _ in self.targets))

    def check_timing(self, f: Fields, timing: Timing) -> None:
        """Each profile within the device's range (0 to ``safety.f_max_n``), steps a hand can settle in, and the
        lead-in plus the profile within the trial cap (and a training trial's length); a target's own profile names
        a target of the protocol."""
        for label, _ in self.targets:
            if timing.targets and label not in timing.targets:
                raise f.fail(f"task.targets.{label}", label,
                             f"must be the label of one of the [[targets]]: {', '.join(timing.targets)}")
        self._check_profile(f, timing, "task.")
        for label, _ in self.targets:  # (a target's field it does not name is this profile's, checked above)
            self.of_target(label)._check_profile(f, timing, f"task.targets.{label}.")

    def _check_profile(self, f: Fields, timing: Timing, where: str) -> None:
        lo, hi = self.range_n()
        limit = timing.ramps.f_max_n
        key = {"ramp": "to_n", "sine": "amplitude_n", "steps": "levels_n"}[self.profile]
        if lo < 0.0 or hi > limit:
            raise f.fail(where + key, self.tables()[0][key],
                         f"the profile spans {lo:g}–{hi:g} N: it must stay within 0–{limit:g} N (safety.f_max_n, "
                         "the device's force limit)")
        if self.profile == "steps" and self.duration_s / len(self.levels_n) < MIN_STEP_S:
            raise f.fail(where + "duration_s", self.duration_s, f"must give each of the {len(self.levels_n)} steps at "
                         f"least {MIN_STEP_S:g} s (a reaction time and a correction)")
        need = self.lead_in_s + self.duration_s
        for fld, cap in (("trial.max_trial_s", timing.max_trial_s),
                         ("training.seconds_per_target_per_mode", timing.training_s)):
            if cap < need:
                raise f.fail(fld, cap, f"must be at least {where}lead_in_s + {where}duration_s = {need:g} s (a "
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
        return self.for_trial(trial).profile_n(t_s)

    def end_ns(self) -> int:
        """The profile's end, ns since the cue: where a tracking trial completes."""
        return int(round((self.lead_in_s + self.duration_s) * 1e9))

    def rule(self, trial: TrialCondition) -> ProfileEnd:
        return ProfileEnd(self.for_trial(trial).end_ns())

    def judge(self, t_ns: npt.ArrayLike, force_n: npt.ArrayLike, trial: TrialCondition, *, max_trial_s: float,
              window: str = "cue", sample_period_s: float = 0.001) -> TrialMetrics:
        p = self.for_trial(trial)
        t, f = capped(t_ns, force_n, max_trial_s, window)
        reached = np.flatnonzero(t >= p.end_ns())
        done = int(reached[0]) if len(reached) else None
        target = p.profile_n(t / 1e9)  # judged keeps a prefix of t: the band's target is the prefix's

        def on_target(force: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
            return np.abs(force - target[:len(force)]) <= p.band_n

        return judged(t, f, done, target_n=lambda times: p.profile_n(times / 1e9), on_target=on_target,
                      max_trial_s=max_trial_s, window=window, sample_period_s=sample_period_s, metrics=self.metrics)

    # -- what it shows and tells ---------------------------------------------------------------------------------
    def cue_text(self, trial: TrialCondition) -> str:
        return f"{trial.target_label} track {self.for_trial(trial).profile_words()}"

    def profile_words(self) -> str:
        """The profile in a few words (``sine 0.8 ± 0.4 N at 0.25 Hz``)."""
        if self.profile == "ramp":
            return f"ramp {self.from_n:g}→{self.to_n:g} N over {self.duration_s:g} s"
        if self.profile == "sine":
            return f"sine {self.offset_n:g} ± {self.amplitude_n:g} N at {self.frequency_hz:g} Hz"
        return f"steps {'/'.join(f'{v:g}' for v in self.levels_n)} N, {self.duration_s / len(self.levels_n):g} s each"

    def screen(self, trial: TrialCondition) -> TrialScreen:
        p = self.for_trial(trial)
        return TrialScreen(
            cue_word=trial.target_label, band=p.band_edges,
            band_label=f"{trial.target_label}: track {p.profile_words()} ± {p.band_n:g} N",
            band_legend=f"target ± {p.band_n:g} N ({p.profile})",
            follow="Follow the target", show_band=self.display != "word",
            ahead_s=self.ahead_s if self.display == "trace_ahead" else 0.0,
        )

    def band_edges(self, t_s: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """The band at trial times ``t_s`` (s since the cue), N: it moves with the profile."""
        f = self.profile_n(t_s)
        return f - self.band_n, f + self.band_n

    def aim(self, trial: TrialCondition, aid: bool) -> TrialAim:
        return self.for_trial(trial).profile_aim(trial.haptic_mode == "on", aid)

    def profile_aim(self, haptics: bool, aid: bool) -> TrialAim:
        """What a simulated participant is told of this profile: the target as knots over trial time."""
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
        return TrialAim(knots, haptics, gauge=aid, practice=aid)

    # -- its words in the report ---------------------------------------------------------------------------------
    def rule_words(self) -> str:
        own = "; ".join(f"{label}: {self.of_target(label).profile_words()}" for label, _ in self.targets)
        return f"track {self.profile_words()}, band ±{self.band_n:g} N" + (f" ({own})" if own else "")

    @classmethod
    def methods(cls, tasks: Sequence[Task], caps: Sequence[float]) -> str:
        mine = [p for t in tasks if isinstance(t, ForceTracking) for p in t.profiles()]
        profiles = "; ".join(sorted({t.profile_words() for t in mine}))
        return (f"The target force follows a profile ({profiles}) after a lead-in of "
                f"{listed([t.lead_in_s for t in mine], ' s')} at its first value; a tracking trial runs the whole "
                f"profile (cap {listed(caps, ' s')}). RMSE and Max AE are taken against the moving target F*(t); a "
                f"sample is in the band when |F − F*(t)| ≤ {listed([t.band_n for t in mine], ' N')}; the lag is the "
                "peak of the cross-correlation between target and task force over the moving part (positive: the "
                "force follows), the gain the least-squares slope of the force on the target there.")
