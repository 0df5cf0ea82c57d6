"""A simulated rig of several arms, from the window's side: which arm the engine must build first.

The engine reads the first arm's records as the session's and hands that arm's stylus to the simulated
participant, so the protocol's task arm must come first -- as ``haptic-study run --sim-arms`` arranges by itself
(:func:`study_app.headless.session_run.sim_arms_of`, the one function both use).  Given in another order
(``gui --sim-arms right,left`` with ``task_arm = "left"``), the window restarts the engine with the task arm first
before the session starts.
"""

from __future__ import annotations

__all__ = ["task_arm_first"]


def task_arm_first(arms: tuple[str, ...], rig: str, protocol_path: str) -> tuple[str, ...]:
    """The simulated rig's ``arms`` (the engine's order) rearranged with the protocol's task arm first, when that
    differs from ``arms``; () when nothing is to change (one arm, the real rig, the order already right, or a
    protocol that does not load or names no arm of the rig: the engine refuses those in one line)."""
    if rig != "sim" or len(arms) < 2:
        return ()
    from protocol.config import ProtocolError, load_protocol
    from study_app.headless.session_run import sim_arms_of  # loads the simulator: only for a rig of several arms

    try:
        order = sim_arms_of(load_protocol(protocol_path or None), arms)
    except (ProtocolError, OSError):
        return ()
    return order if order != arms else ()
