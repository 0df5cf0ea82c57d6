"""A simulated rig of several arms, from the window's side: which arm the engine must build first.

The engine reads the first arm's records as the session's and hands that arm's stylus to the simulated
participant, so the protocol's task arm must come first -- as ``haptic-study run --sim-arms`` arranges by itself
(:func:`study_app.headless.session_run.sim_arms_of`, the one function both use).  Given in another order
(``gui --sim-arms right,left`` with ``task_arm = "left"``), the window restarts the engine with the task arm first
before the session starts; an interrupted session is resumed on the arms in the order it ran on
(:func:`stored_arm_order`).
"""

from __future__ import annotations

__all__ = ["stored_arm_order", "task_arm_first"]


def task_arm_first(arms: tuple[str, ...], rig: str, protocol_path: str) -> tuple[str, ...]:
    """The simulated rig's ``arms`` (the engine's order) rearranged with the protocol's task arm first, when that
    differs from ``arms``; () when nothing is to change (one arm, the real rig, the order already right, or a
    protocol that does not load or names no arm of the rig: the engine refuses those in one line)."""
    if rig != "sim" or len(arms) < 2:
        return ()
    from protocol.study.config import ProtocolError, load_protocol
    from study_app.headless.session_run import sim_arms_of  # loads the simulator: only for a rig of several arms

    try:
        order = sim_arms_of(load_protocol(protocol_path or None), arms)
    except (ProtocolError, OSError):
        return ()
    return order if order != arms else ()


def stored_arm_order(arms: tuple[str, ...], rig: str, stored: object) -> tuple[str, ...]:
    """The order an interrupted session ran its arms in (``stored``, its task arm first, as listed with the
    resumable sessions), when it is ``arms`` (the simulated rig's, in the engine's order) rearranged; () when
    nothing is to change (the same order, the real rig, or other arms: the engine refuses those in one line,
    naming the ``--sim-arms`` to restart with)."""
    order = tuple(str(a) for a in stored) if isinstance(stored, (list, tuple)) else ()
    if rig != "sim" or len(arms) < 2 or order == arms or sorted(order) != sorted(arms):
        return ()
    return order
