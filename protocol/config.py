"""The study protocol as data: load and validate a protocol TOML file.

A protocol names the targets, the haptic modes, the trial counts and timing,
the ordering method and the training block.  :func:`load_protocol` checks
every field and raises one :class:`ProtocolError` that names the field, the
offending value and what is allowed -- nothing starts with a bad file.
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from dataclasses import asdict, dataclass
from importlib import resources
from pathlib import Path
from typing import Any

__all__ = [
    "ABORT_POLICIES",
    "ORDERINGS",
    "ProtocolConfig",
    "ProtocolError",
    "Target",
    "TrainingConfig",
    "TrialTiming",
    "default_protocol",
    "load_protocol",
    "protocol_from_dict",
]

ORDERINGS = ("random", "blocked_by_mode", "counterbalanced")
ABORT_POLICIES = ("append", "reinsert")
MODES = ("on", "off")
_LABEL = re.compile(r"^[A-Z][A-Z0-9_]{0,15}\Z")  # \Z, not $: "$" also matches before a final newline


class ProtocolError(ValueError):
    """A protocol file or value is invalid; the message names field, value and what is allowed."""


@dataclass(frozen=True, slots=True)
class Target:
    """A target force and the word the participant sees."""

    label: str
    force_n: float


@dataclass(frozen=True, slots=True)
class TrialTiming:
    """Success criterion and timing of each trial (paper §V-B)."""

    tolerance_fraction: float = 0.10
    hold_s: float = 1.0
    max_trial_s: float = 12.0
    pause_s: float = 2.0
    cue_s: float = 1.0


@dataclass(frozen=True, slots=True)
class TrainingConfig:
    """Free-practice block before the experiment."""

    enabled: bool = True
    seconds_per_target_per_mode: float = 20.0
    live_force_aid: bool = True


@dataclass(frozen=True, slots=True)
class ProtocolConfig:
    """A validated study protocol."""

    name: str
    targets: tuple[Target, ...]
    modes: tuple[str, ...]
    trials_per_cell: int
    ordering: str
    abort_policy: str
    trial: TrialTiming
    training: TrainingConfig
    version: int = 1

    @property
    def trials_per_participant(self) -> int:
        """Targets × modes × trials per cell (20 for the paper)."""
        return len(self.targets) * len(self.modes) * self.trials_per_cell

    def target(self, label: str) -> Target:
        """The target with this label."""
        for t in self.targets:
            if t.label == label:
                return t
        raise KeyError(label)

    def to_dict(self) -> dict[str, Any]:
        """Plain data in the file's structure (stored with each session)."""
        return {
            "name": self.name,
            "version": self.version,
            "targets": [asdict(t) for t in self.targets],
            "design": {
                "modes": list(self.modes),
                "trials_per_cell": self.trials_per_cell,
                "ordering": self.ordering,
                "abort_policy": self.abort_policy,
            },
            "trial": asdict(self.trial),
            "training": asdict(self.training),
        }

    def to_json(self) -> str:
        """Canonical JSON of :meth:`to_dict`."""
        return json.dumps(self.to_dict(), sort_keys=True)


def _fail(source: str, field: str, value: Any, allowed: str) -> ProtocolError:
    return ProtocolError(f"{source}: {field} = {value!r}: {allowed}")


def _number(src: str, field: str, v: Any, *, lo: float, hi: float, lo_open: bool = True) -> float:
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    ok = ok and (v > lo if lo_open else v >= lo) and v <= hi
    if not ok:
        rng = f"{'>' if lo_open else '≥'} {lo:g} and ≤ {hi:g}"
        raise _fail(src, field, v, f"must be a number {rng}")
    return float(v)


def _table(src: str, field: str, v: Any, allowed_keys: set[str]) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise _fail(src, field, v, "must be a table")
    extra = set(v) - allowed_keys
    if extra:
        key = sorted(extra)[0]
        raise _fail(src, f"{field}.{key}" if field else key, v[key], f"unknown field; allowed: {', '.join(sorted(allowed_keys))}")
    return v


def protocol_from_dict(d: Any, source: str = "protocol") -> ProtocolConfig:
    """Validate plain data (a parsed TOML file) into a :class:`ProtocolConfig`."""
    top = _table(source, "", d, {"name", "version", "targets", "design", "trial", "training"})
    name = top.get("name", "unnamed protocol")
    if not isinstance(name, str) or not name.strip():
        raise _fail(source, "name", name, "must be a non-empty string")
    version = top.get("version", 1)
    if version != 1:
        raise _fail(source, "version", version, "this software reads protocol version 1")

    raw_targets = top.get("targets")
    if not isinstance(raw_targets, list) or not 1 <= len(raw_targets) <= 8:
        raise _fail(source, "targets", raw_targets, "must be a list of 1 to 8 [[targets]] tables")
    targets = []
    for i, t in enumerate(raw_targets):
        f = f"targets[{i}]"
        t = _table(source, f, t, {"label", "force_n"})
        label = t.get("label")
        if not isinstance(label, str) or not _LABEL.match(label):
            raise _fail(source, f"{f}.label", label, "must be an upper-case word of 1–16 letters/digits/_ (e.g. GENTLE)")
        force = _number(source, f"{f}.force_n", t.get("force_n"), lo=0.0, hi=20.0)
        targets.append(Target(label, force))
    labels = [t.label for t in targets]
    if len(set(labels)) != len(labels):
        raise _fail(source, "targets", labels, "labels must be unique")

    design = _table(source, "design", top.get("design", {}), {"modes", "trials_per_cell", "ordering", "abort_policy"})
    modes = design.get("modes", list(MODES))
    if (
        not isinstance(modes, list) or not modes or len(set(modes)) != len(modes)
        or any(m not in MODES for m in modes)
    ):
        raise _fail(source, "design.modes", modes, "must be a non-empty list of distinct values from 'on', 'off'")
    per_cell = design.get("trials_per_cell", 5)
    if isinstance(per_cell, bool) or not isinstance(per_cell, int) or not 1 <= per_cell <= 100:
        raise _fail(source, "design.trials_per_cell", per_cell, "must be a whole number from 1 to 100")
    ordering = design.get("ordering", "random")
    if ordering not in ORDERINGS:
        raise _fail(source, "design.ordering", ordering, f"allowed values: {', '.join(ORDERINGS)}")
    policy = design.get("abort_policy", "append")
    if policy not in ABORT_POLICIES:
        raise _fail(source, "design.abort_policy", policy, f"allowed values: {', '.join(ABORT_POLICIES)}")

    tr = _table(source, "trial", top.get("trial", {}), {"tolerance_fraction", "hold_s", "max_trial_s", "pause_s", "cue_s"})
    timing = TrialTiming(
        tolerance_fraction=_number(source, "trial.tolerance_fraction", tr.get("tolerance_fraction", 0.10), lo=0.0, hi=0.5),
        hold_s=_number(source, "trial.hold_s", tr.get("hold_s", 1.0), lo=0.0, hi=60.0),
        max_trial_s=_number(source, "trial.max_trial_s", tr.get("max_trial_s", 12.0), lo=0.0, hi=600.0),
        pause_s=_number(source, "trial.pause_s", tr.get("pause_s", 2.0), lo=0.0, hi=600.0, lo_open=False),
        cue_s=_number(source, "trial.cue_s", tr.get("cue_s", 1.0), lo=0.0, hi=60.0, lo_open=False),
    )
    if timing.hold_s >= timing.max_trial_s:
        raise _fail(source, "trial.hold_s", timing.hold_s, f"must be shorter than trial.max_trial_s = {timing.max_trial_s:g}")

    trn = _table(source, "training", top.get("training", {}), {"enabled", "seconds_per_target_per_mode", "live_force_aid"})
    enabled = trn.get("enabled", True)
    if not isinstance(enabled, bool):
        raise _fail(source, "training.enabled", enabled, "must be true or false")
    aid = trn.get("live_force_aid", True)
    if not isinstance(aid, bool):
        raise _fail(source, "training.live_force_aid", aid, "must be true or false")
    training = TrainingConfig(
        enabled=enabled,
        seconds_per_target_per_mode=_number(
            source, "training.seconds_per_target_per_mode", trn.get("seconds_per_target_per_mode", 20.0), lo=0.0, hi=3600.0
        ),
        live_force_aid=aid,
    )
    return ProtocolConfig(
        name=name.strip(), targets=tuple(targets), modes=tuple(modes), trials_per_cell=per_cell,
        ordering=ordering, abort_policy=policy, trial=timing, training=training, version=1,
    )


def load_protocol(path: str | Path | None = None) -> ProtocolConfig:
    """Load and validate a protocol file (default: the paper's study, ``protocol/default.toml``)."""
    if path is None:
        text = resources.files("protocol").joinpath("default.toml").read_text(encoding="utf-8")
        source = "protocol/default.toml"
    else:
        p = Path(path)
        source = str(p)
        try:
            text = p.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise ProtocolError(f"{source}: no such protocol file") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ProtocolError(f"{source}: cannot read the protocol file ({exc})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProtocolError(f"{source}: not valid TOML ({exc})") from None
    return protocol_from_dict(data, source)


def default_protocol() -> ProtocolConfig:
    """The paper's study."""
    return load_protocol(None)
