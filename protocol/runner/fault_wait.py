"""The fault waiting and reset policy of a session: no cue while a fault is latched, and who resets it.

Every loop event (a fault latched with the value that tripped it, a condition gone, a reset) is stored as an event
(:meth:`FaultWait.store`); on a rig of several arms another arm's event is stored with its arm's name and does not
name the trial's fault (the task arm sees that arm only through its own ``OTHER_ARM`` latch).  No trial is cued
while a fault is latched; once it is cleared the protocol's pause runs again before the next cue
(:meth:`FaultWait.between_trials`).  In a headless session (``auto_reset``) the runner itself resets a fault in the
pause once its condition is gone (or every :data:`RESET_RETRY_S` while it may be); if one is still latched
:data:`FAULT_TIMEOUT_S` later the session stops as *interrupted*, resumable later.  A person's session leaves the
reset to the experimenter.
"""

from __future__ import annotations

from pipeline.devices.interfaces import Fault
from pipeline.runtime.loop_messages import LoopEvent, ResetFaults
from protocol.runner.session_desk import SessionDesk

__all__ = ["FAULT_TIMEOUT_S", "RESET_RETRY_S", "FaultWait"]

#: Headless: a latched fault is reset at most this often while its condition may still be there.
RESET_RETRY_S = 0.5
#: Headless: a fault still latched this long after the runner started waiting stops the session (interrupted).
FAULT_TIMEOUT_S = 10.0


class FaultWait:
    """A session's latched faults between trials: stored, waited for, reset (headless), or the session interrupted.

    Parameters
    ----------
    desk
        The session's events, commands and progress.
    pause_s
        The protocol's pause, run again before the next cue once a fault is cleared.
    auto_reset
        Headless: reset a latched fault once its condition is gone, and interrupt the session if one stays
        latched :data:`FAULT_TIMEOUT_S`.
    arms, task_arm
        The rig's arms (more than one: each event names its arm) and the arm whose faults are the trial's.
    """

    def __init__(self, desk: SessionDesk, pause_s: float, auto_reset: bool, arms: tuple[str, ...],
                 task_arm: str) -> None:
        self.desk = desk
        self.pause_s = pause_s
        self.auto_reset = auto_reset
        self.arms, self.task_arm = arms, task_arm
        #: The faults latched, as the newest record says.
        self.latched = 0
        #: The newest fault event's detail: names the cause of the trial a fault aborts.
        self.detail = ""
        self._condition_gone = False  # the loop said a latched fault's condition went away
        self._waiting_since_ns: int | None = None
        self._next_reset_ns = 0

    def store(self, ev: LoopEvent) -> None:
        """Store one of the loop's events (on a rig of several arms, named by its arm)."""
        if len(self.arms) > 1 and ev.arm != self.task_arm:
            # another arm's event: stored with its arm; the task's trial sees that arm only through the task arm's
            # own records (its OTHER_ARM fault under the policy "both"), so it does not name the trial's fault
            self.desk.event(int(ev.t_ns), ev.kind, f"arm {ev.arm}: {self._detail(ev)}")
            return
        if ev.kind == "fault":
            self.detail = ev.detail
            self._condition_gone = False
        elif ev.kind == "fault_cleared":
            self._condition_gone = True  # a reset can clear it now
        detail = self._detail(ev)
        self.desk.event(int(ev.t_ns), ev.kind, f"arm {ev.arm}: {detail}" if len(self.arms) > 1 else detail)

    @staticmethod
    def _detail(ev: LoopEvent) -> str:  # what the events table keeps of a loop event
        if ev.kind != "faults_reset":
            return ev.detail
        return f"cleared {ev.detail}" if not ev.faults else \
            f"{Fault(ev.faults).describe()} still latched (its condition persists)"

    def between_trials(self, t_ns: int) -> int | None:
        """No trial runs at loop time ``t_ns``: wait for a latched fault (headless: reset it), or -- the fault just
        cleared -- return the loop time before which the next cue must not come (None: no new hold)."""
        if self.latched:
            self._wait(t_ns)
            return None
        if self._waiting_since_ns is None:
            return None
        # the fault is cleared: the protocol's pause runs again before the next cue
        self._waiting_since_ns = None
        self.desk.state.waiting = ""
        self.desk.event(t_ns, "waiting", f"faults cleared; the next cue follows a {self.pause_s:g} s pause")
        return t_ns + int(round(self.pause_s * 1e9))

    def _wait(self, t_ns: int) -> None:
        """A fault is latched outside a trial: hold the next cue; headless, reset it once it can be."""
        what = Fault(self.latched).describe()
        desk = self.desk
        if self._waiting_since_ns is None:
            self._waiting_since_ns = t_ns
            # reset at once when the loop said the condition is gone, else try every RESET_RETRY_S (a device
            # error or an operator stop only clears with a reset)
            self._next_reset_ns = t_ns + int(RESET_RETRY_S * 1e9)
            how = "the runner resets it once its condition is gone" if self.auto_reset else \
                "the experimenter resets it"
            desk.event(t_ns, "waiting", f"{what} latched: no cue until it is reset ({how})")
        desk.state.waiting = f"fault latched ({what}): reset to continue"
        if not self.auto_reset:
            return
        if t_ns - self._waiting_since_ns > int(FAULT_TIMEOUT_S * 1e9):
            desk.interrupt(t_ns, f"{what} was still latched {FAULT_TIMEOUT_S:g} s after the runner began waiting "
                                 "for it to clear; the session is interrupted and can be resumed")
            return
        if self._condition_gone or t_ns >= self._next_reset_ns:
            self._condition_gone = False
            self._next_reset_ns = t_ns + int(RESET_RETRY_S * 1e9)
            desk.submit(ResetFaults())
