"""``haptic-study sim``: the scripted simulated rig on either clock."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import study_app.cli.sim_summary as sim_summary


@pytest.fixture
def records(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """Capture the records the summary is computed from."""
    seen: dict[str, Any] = {}
    summarise = sim_summary._summarise

    def spy(d: dict[str, np.ndarray], *args: Any) -> dict[str, Any]:
        seen.update(d)
        return summarise(d, *args)

    monkeypatch.setattr(sim_summary, "_summarise", spy)
    return seen


def test_real_clock_run_keeps_feedback_on_for_the_whole_run(records: dict[str, Any]) -> None:
    """1.5 s in real time (the one real-clock run here): one loop run, not one per ring chunk.

    Each ``HapticLoop.run`` ramps the force down when it ends; cut into 1 s
    chunks, feedback went off after the first second.
    """
    s = sim_summary.run_scripted_sim(seconds=1.5, clock="real")
    gain, t = records["gain"], records["t_s"]
    assert s["loop"]["ticks"] == len(gain) - 1
    # ramped in by 0.5 s, on until the end of the run.  On a loaded machine a tick can come later than the
    # Touch's command timeout: the device has dropped the force and the output restarts from zero at that tick.
    # On that tick the gain is one ramp-in step from zero: a late tick counts as at most 5 ms of the 0.5 s ramp
    # (tests/pipeline/test_loop_stall.py pins this on the virtual clock), so at most 0.01.
    # Anything else -- a gradual fall, as a ramp-down at a chunk boundary -- is a failure.
    late = np.diff(t, prepend=t[0]) >= 0.010
    falls = np.flatnonzero(np.diff(gain[:1500]) < 0) + 1
    assert all(late[k] and gain[k] <= 0.005 / 0.5 for k in falls), [
        (int(k), float(t[k] - t[k - 1]), float(gain[k])) for k in falls]
    if not late[:1500].any():
        assert np.all(gain[500:1500] == 1.0)
    assert np.all(gain[1500:] < 1.0) and gain[-1] == 0.0  # then the run's own ramp-down, to zero
    assert np.all(np.diff(t) > 0)  # every record once, in order


def test_virtual_clock_run_is_deterministic(records: dict[str, Any]) -> None:
    a = sim_summary.run_scripted_sim(seconds=2.0, seed=3)
    b = sim_summary.run_scripted_sim(seconds=2.0, seed=3)
    for timing in ("wall_s", "speed_x_real_time"):  # the only wall-clock figures
        del a[timing], b[timing]
    assert a == b
    assert len(records["gain"]) == 2000 and records["gain"][-1] == 1.0
