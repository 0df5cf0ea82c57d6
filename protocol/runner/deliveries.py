"""What the loop delivered to each trial of a session, and why an aborted trial did not count.

**A trial counts only if it ran under its designed condition**: the runner aborts it at the first record where the
loop did not deliver it as designed (:meth:`Deliveries.deviation`, the checks of :mod:`protocol.study.delivery`),
or when records were lost before the runner could read them (:meth:`Deliveries.lost`).  An aborted trial's cause
is kept until its record is made (:meth:`Deliveries.settle`); trials the loop failed to deliver in a row are counted,
so a machine or rig that cannot hold the designed condition stops the cueing (:data:`MAX_FAILED_IN_A_ROW`) instead of
re-running trials without end.
"""

from __future__ import annotations

import numpy as np

from protocol.study.delivery import DeliveryLimits, Deviation, TrialWindow
from protocol.study.records import AbortCause
from protocol.study.trial import TrialMachine, TrialPhase

__all__ = ["MAX_FAILED_IN_A_ROW", "Deliveries"]

#: Trials in a row the loop failed to deliver (fault, feedback, gap) before the runner stops cueing: a machine or
#: rig that cannot hold the designed condition would otherwise re-run trials without end.
MAX_FAILED_IN_A_ROW = 3


class Deliveries:
    """The running trial's records and loop health, where it left its designed condition, why trials were aborted.

    Parameters
    ----------
    limits
        What the loop must deliver for a trial to count.
    """

    def __init__(self, limits: DeliveryLimits) -> None:
        self.limits = limits
        #: The running trial's records: the ticks of its first and last, and their loop health.
        self.window = TrialWindow()
        #: Trials the loop did not deliver as designed, since the last that it did.
        self.failed_in_a_row = 0
        self._causes: dict[int, AbortCause] = {}  # trial index -> cause of its abort
        self._gap = ""  # records lost before the next block

    def lost(self, count: int) -> None:
        """``count`` records could not be read (the ring lapped the reader): the running trial has a gap."""
        self._gap = f"{count} loop records were lost before they could be stored"

    def take_gap(self) -> str:
        """The gap noted since the last block ("" for none), taken."""
        gap, self._gap = self._gap, ""
        return gap

    def deviation(self, rows: np.ndarray, machine: TrialMachine, fault_detail: str) -> Deviation | None:
        """The first record at which the running trial left its designed condition (None: no trial, or none)."""
        if machine.phase not in (TrialPhase.CUED, TrialPhase.ACTIVE) or machine.spec is None:
            return None
        return self.window.deviation(rows, machine.spec, machine.cue_ns, self.limits, fault_detail)

    def aborting(self, trial_index: int, cause: AbortCause | str) -> None:
        """The trial is being aborted for ``cause`` (its record, made next, stores it)."""
        self._causes[trial_index] = AbortCause(cause)

    def settle(self, trial_index: int, aborted: bool) -> AbortCause | None:
        """A trial ended: its abort cause (None: it counts), and whether it adds to the trials failed in a row."""
        cause = self._causes.pop(trial_index, AbortCause.EXPERIMENTER) if aborted else None
        self.failed_in_a_row = self.failed_in_a_row + 1 if cause is not None and cause.undelivered else 0
        return cause

    @property
    def too_many_failed(self) -> bool:
        """Too many trials in a row were not delivered as designed: stop cueing."""
        return self.failed_in_a_row >= MAX_FAILED_IN_A_ROW
