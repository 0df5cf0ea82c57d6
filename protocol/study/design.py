"""Trial conditions and the seeded, balanced schedule.

The whole schedule is computed before the first trial and stored with the
session (PsychoPy's precomputed ``upcoming``), so it can be shown, logged,
tested and resumed.  Each target × mode cell occurs exactly
``trials_per_cell`` times.  Ordering methods:

``random``
    All trials shuffled together -- the paper's "fully automated and
    randomized" order.
``blocked_by_mode``
    All trials of one mode, then all of the other; which mode comes first is
    drawn from the seed; targets are shuffled within each block.
``counterbalanced``
    Blocked by mode, with the mode order alternating across participants:
    participant 1, 3, 5 … start with the first mode of ``design.modes``
    ("on" in the default protocol), participants 2, 4, 6 … with the other, so
    a study with an even number of participants balances order effects.

Same protocol, seed and participant number → the same schedule.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from enum import StrEnum

import numpy as np

from protocol.study.config import ProtocolConfig

__all__ = ["HapticMode", "TrialSpec", "build_schedule", "requeue_aborted", "schedule_from_json", "schedule_to_json"]


class HapticMode(StrEnum):
    """Haptic feedback condition of a trial."""

    ON = "on"
    OFF = "off"


@dataclass(frozen=True, slots=True)
class TrialSpec:
    """One scheduled trial. ``index`` is its position in the session (0-based)."""

    index: int
    target_label: str
    target_force_n: float
    haptic_mode: HapticMode
    repeat_of: int | None = None  # index of the aborted trial this one re-runs

    def __post_init__(self) -> None:
        # a mode read from a protocol file or a stored schedule ("on"/"off") becomes the enum (the same TEXT)
        object.__setattr__(self, "haptic_mode", HapticMode(self.haptic_mode))


def _cells(p: ProtocolConfig, modes: tuple[str, ...]) -> list[tuple[str, float, str]]:
    return [(t.label, t.force_n, m) for m in modes for t in p.targets for _ in range(p.trials_per_cell)]


def build_schedule(protocol: ProtocolConfig, seed: int, participant_number: int = 1) -> list[TrialSpec]:
    """The balanced trial order for one participant.

    Parameters
    ----------
    protocol
        The validated protocol.
    seed
        Session seed; with the protocol and participant number it fixes the order.
    participant_number
        1-based position of the participant in the study (used by ``counterbalanced``).
    """
    if participant_number < 1:
        raise ValueError(f"participant_number = {participant_number}: must be ≥ 1")
    rng = np.random.default_rng([seed, participant_number])
    modes = protocol.modes
    if protocol.ordering == "random":
        cells = _cells(protocol, modes)
        order = rng.permutation(len(cells)).tolist()
        seq = [cells[i] for i in order]
    else:
        if protocol.ordering == "blocked_by_mode":
            mode_order = [modes[i] for i in rng.permutation(len(modes)).tolist()]
        else:  # counterbalanced
            shift = (participant_number - 1) % len(modes)
            mode_order = list(modes[shift:] + modes[:shift])
        seq = []
        for m in mode_order:
            block = _cells(protocol, (m,))
            seq.extend(block[i] for i in rng.permutation(len(block)).tolist())
    return [TrialSpec(i, label, force, mode) for i, (label, force, mode) in enumerate(seq)]


def requeue_aborted(
    schedule: list[TrialSpec], aborted: TrialSpec, next_position: int, policy: str, rng: np.random.Generator
) -> list[TrialSpec]:
    """Schedule a re-run of an aborted trial and renumber the trials after it.

    ``append`` puts it at the end; ``reinsert`` at a random position among the
    trials not yet run (``next_position`` and later).  Trials already run keep
    their indices; the schedule stays balanced because the aborted trial does
    not count.
    """
    rerun = (aborted.target_label, aborted.target_force_n, aborted.haptic_mode)
    done, todo = schedule[:next_position], schedule[next_position:]
    pos = len(todo) if policy == "append" else int(rng.integers(0, len(todo) + 1))
    items = [(t.target_label, t.target_force_n, t.haptic_mode, t.repeat_of) for t in todo]
    items.insert(pos, (*rerun, aborted.index))
    return done + [TrialSpec(next_position + k, a, f, m, r) for k, (a, f, m, r) in enumerate(items)]


def schedule_to_json(schedule: list[TrialSpec]) -> str:
    """Serialise for the ``sessions.schedule_json`` column."""
    return json.dumps([asdict(t) for t in schedule])


def schedule_from_json(text: str) -> list[TrialSpec]:
    """Inverse of :func:`schedule_to_json`."""
    return [TrialSpec(**d) for d in json.loads(text)]
