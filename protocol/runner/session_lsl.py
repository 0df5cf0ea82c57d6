"""A session run on the Lab Streaming Layer, for every process that runs one (the headless runner, the study engine).

:func:`lsl_streams_of` finds the external streams the protocol names before anything is stored (a stream not found
within its timeout, or pylsl missing, is the one-line refusal of :mod:`protocol.lsl.bus`); :func:`attach_lsl`
opens the run's outlets and taps once its runner is made, on the loop's clock; :func:`detach_lsl` closes them when
the run ends, before its writer closes.  A protocol that asks nothing of LSL costs nothing: no call here does
anything for it.
"""

from __future__ import annotations

from typing import Any

from foundation.errors import InputRefused
from protocol.lsl.bus import pylsl, resolve_streams
from protocol.lsl.outlets import SessionIds
from protocol.lsl.streams import open_session_streams
from protocol.runner.session import SessionRunner
from protocol.runner.session_setup import OpenedSession
from protocol.study.lsl_settings import LslSettings

__all__ = ["attach_lsl", "detach_lsl", "lsl_skipped", "lsl_streams_of"]


def lsl_streams_of(settings: LslSettings) -> list[Any]:
    """The external streams ``settings`` names, resolved (none asked: [] without importing pylsl)."""
    if not settings.record:
        return []
    return resolve_streams(settings.record, settings.resolve_timeout_s)


def attach_lsl(runner: SessionRunner, opened: OpenedSession, loop_t0_ns: int, infos: list[Any] | None = None) -> None:
    """Open the run's LSL if its protocol asks for it (outlets, taps on ``infos`` or the streams found now).

    ``loop_t0_ns`` is the loop's first tick on its real clock (``loop.t0_ns``): the records' times count from it.
    """
    settings = opened.protocol.lsl
    if not settings.on:
        return
    if infos is None:
        infos = lsl_streams_of(settings)
    ids = SessionIds(study=f"{opened.protocol.name} (seed {opened.seed})", participant=opened.code,
                     session_id=opened.session_id, kind=opened.kind)

    def event(t_ns: int, kind: str, detail: str) -> None:
        runner.recorder.event(runner.session_id, runner.session_time_s(t_ns), kind, detail)

    def now_event(kind: str, detail: str) -> None:  # (from a tap's thread: the recorder's queue takes it)
        t_ns = int(streams.link.records_ns(float(pylsl().local_clock())))
        event(t_ns, kind, detail)

    try:
        streams = open_session_streams(settings, ids, opened.protocol.task, recorder=runner.recorder,
                                       segment=opened.segment, loop_t0_ns=loop_t0_ns, infos=infos, event=event,
                                       now_event=now_event)
    except InputRefused:
        raise
    except Exception as exc:  # LSL that cannot open is an event of the session, which runs without it
        runner.recorder.event(runner.session_id, opened.clock_offset_s, "lsl",
                              f"LSL not opened: {type(exc).__name__}: {exc}; the session runs without it")
        return
    runner.attach_lsl(streams)


def lsl_skipped(runner: SessionRunner, opened: OpenedSession) -> None:
    """A run on the virtual clock of a session whose protocol asks for LSL (a headless resume): nothing is published
    or recorded, and the session says so."""
    runner.recorder.event(runner.session_id, opened.clock_offset_s, "lsl",
                          "not on LSL: a virtual-clock run's times are on no clock LSL shares (run it with --clock "
                          "real to publish and record)")


def detach_lsl(runner: SessionRunner) -> None:
    """Close the run's LSL (the taps' last samples handed to the writer first)."""
    if runner.lsl is not None:
        runner.lsl.close()
