"""The checks of ``haptic-study qualify`` on one arm's real haptic device (docs/qualify.md says each one's source).

* **process death**: a child process opens the device through its backend and commands a force; once the device
  reports rendering it, the parent kills the child at once (``SIGKILL``: no clean-up, no final zero) and, no sooner
  than :data:`ZERO_WITHIN_S` after the kill, opens the device without a servo scheduler and reads what it renders.
  The verdict rests on that one read (taken late, never early, so a loaded machine cannot fail a correct device);
  the time it was taken is recorded, and a first read right after the kill is recorded for information.
* **thermal budget**: the device's own peak and continuous ratings run through the product's motor-heat model
  (:class:`pipeline.devices.touch_output.TouchOutput`) on a stepped clock: a peak force held past the budget must
  be derated to the continuous rating, the rendered force never above the derated limit, the heat never past the
  budget (docs/hardware.md, pipeline/devices/touch_output.py).

A check a device cannot do is ``NOT CHECKED`` with why, never a pass.
"""

from __future__ import annotations

import json
import math
import queue
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass
from typing import Any

#: Every fault reaches zero within 50 ms (the house's safety rule; the loop's dead-loop supervisor's bound).
ZERO_WITHIN_S = 0.050
#: A force the device reports after the kill at most this large is zero, N (an encoder-quantised read of an
#: unpowered motor; the fakes report exactly 0).
ZERO_TOLERANCE_N = 1e-3
#: The child must report holding its force within this long (opening a Touch takes ~1 s).
_CHILD_READY_S = 20.0
#: The child's commanded force as a fraction of the device's continuous rating: held without warming the motors.
_HOLD_FRACTION = 0.5
#: Of the commanded force, at least this much must be reported before the kill for the check to mean anything.
_HELD_FRACTION = 0.5
#: The thermal run: this long of a held peak force on the stepped clock, s (the Touch derates to within 1% of its
#: continuous rating in ~37 s).
_THERMAL_RUN_S = 120.0


@dataclass(frozen=True, slots=True)
class CheckResult:
    """One check's outcome: what was measured, against what bound, and the verdict (``PASS``, ``FAIL`` or
    ``NOT CHECKED``); ``why`` says why a check failed or was not done."""

    name: str
    verdict: str
    measured: str = ""
    bound: str = ""
    why: str = ""

    def as_dict(self) -> dict[str, str]:
        """Plain data for the qualification record."""
        return asdict(self)


def not_checked(name: str, why: str, bound: str = "") -> CheckResult:
    """A check not done, and why."""
    return CheckResult(name, "NOT CHECKED", bound=bound, why=why)


def _magnitude(f: Any) -> float:
    return math.hypot(*(float(v) for v in f))


def _read_line(stream: Any, timeout_s: float) -> str | None:
    """The next line of ``stream`` within ``timeout_s`` (a reader thread: pipes have no timeout on Windows)."""
    got: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: got.put(stream.readline()), daemon=True).start()
    try:
        return got.get(timeout=timeout_s) or None
    except queue.Empty:
        return None


def process_death(hardware: str, arm: Any) -> CheckResult:
    """The process-death check on ``arm`` (:class:`pipeline.settings.hardware.ArmSettings`) of file ``hardware``."""
    from foundation.platform_support.processes import kill_hard
    from pipeline.devices.registry import haptic_model

    name = "process-death"
    bound = f"|F| <= {ZERO_TOLERANCE_N:g} N, read >= {ZERO_WITHIN_S * 1e3:g} ms after SIGKILL"
    if haptic_model(arm.haptic.model).key != "touch":
        return not_checked(name, f"the {arm.haptic.model!r} device cannot report the force it renders", bound)
    child = subprocess.Popen([sys.executable, "-m", "study_app.cli.qualify_checks", hardware, arm.name],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = _read_line(child.stdout, _CHILD_READY_S)
        if line is None:
            kill_hard(child.pid)
            child.wait(10.0)
            err = (child.stderr.read() if child.stderr else "").strip().splitlines()
            return not_checked(name, "the device could not be driven: " + (err[-1] if err else "no answer"), bound)
        held = json.loads(line)
        if _magnitude(held["reported_n"]) < _HELD_FRACTION * _magnitude(held["commanded_n"]):
            kill_hard(child.pid)
            return not_checked(name, f"the device reported {_magnitude(held['reported_n']):.3f} N of the "
                               f"{_magnitude(held['commanded_n']):.3f} N commanded before the kill", bound)
        t_kill = time.monotonic()
        kill_hard(child.pid)
        child.wait(10.0)
    finally:
        if child.poll() is None:
            kill_hard(child.pid)
            child.wait(10.0)
        for stream in (child.stdout, child.stderr):
            if stream is not None:
                stream.close()
    return _read_after_kill(name, bound, arm, t_kill, _magnitude(held["reported_n"]))


def _read_after_kill(name: str, bound: str, arm: Any, t_kill: float, held_n: float) -> CheckResult:
    """Read the device right after the kill (for information) and no sooner than the bound (the verdict)."""
    from pipeline.backends.touch import read_back_force
    from pipeline.devices.interfaces import DeviceError

    try:
        first = _magnitude(read_back_force(arm.haptic.device_name, arm.haptic.dll_dir))
        t_first = time.monotonic() - t_kill
        wait = ZERO_WITHIN_S - (time.monotonic() - t_kill)
        if wait > 0:
            time.sleep(wait)  # a wait for the bound to pass, not a timing assertion: the read is never early
        after = _magnitude(read_back_force(arm.haptic.device_name, arm.haptic.dll_dir))
        t_after = time.monotonic() - t_kill
    except DeviceError as exc:
        return not_checked(name, f"the device could not be read after the kill: {exc}", bound)
    measured = (f"{held_n:.3f} N held; {first:.3f} N at {t_first * 1e3:.1f} ms, {after:.4f} N at "
                f"{t_after * 1e3:.1f} ms after SIGKILL")
    if after <= ZERO_TOLERANCE_N:
        return CheckResult(name, "PASS", measured, bound)
    return CheckResult(name, "FAIL", measured, bound, why="the device kept its force after its process died")


def thermal_budget(arm: Any) -> CheckResult:
    """The thermal-budget check on ``arm``'s device ratings (opened once to read them)."""
    from pipeline.assembly.real_rig import open_haptic
    from pipeline.core.clock import MonotonicClock
    from pipeline.devices.interfaces import DeviceError
    from pipeline.devices.registry import haptic_model
    from pipeline.devices.touch_output import HapticLimits

    name = "thermal-budget"
    try:
        dev = open_haptic(arm.haptic, MonotonicClock())
    except (DeviceError, OSError, ValueError) as exc:
        return not_checked(name, f"the device could not be opened: {exc}")
    try:
        peak, cont = float(dev.peak_force_n), float(dev.continuous_force_n)
    finally:
        dev.close()
    model = haptic_model(arm.haptic.model).limits
    return run_thermal(HapticLimits(peak, cont, model.thermal_budget_n2s, model.derate_from_fraction),
                       arm.haptic.command_timeout_s)


def run_thermal(spec: Any, command_timeout_s: float, dt_ns: int = 1_000_000) -> CheckResult:
    """Hold ``spec``'s peak force for :data:`_THERMAL_RUN_S` on a stepped clock (1 ms servo ticks) through the
    product's :class:`pipeline.devices.touch_output.TouchOutput`; the verdict of its derating."""
    from pipeline.devices.touch_output import TouchOutput

    out = TouchOutput(spec, command_timeout_s)
    cont, peak = spec.continuous_force_n, spec.peak_force_n
    over_limit = 0.0  # the most the rendered force ever exceeded the derated limit, N
    derated_at = math.nan
    t_ns = 0
    for _ in range(int(_THERMAL_RUN_S * 1e9) // dt_ns):
        limit = out.limit_n
        out.command(0.0, 0.0, peak, t_ns)
        f = _magnitude(out.render(t_ns, dt_ns * 1e-9))
        over_limit = max(over_limit, f - limit)
        if math.isnan(derated_at) and out.limit_n <= cont * 1.01:
            derated_at = t_ns * 1e-9
        t_ns += dt_ns
    final = out.rendered_n[2]
    bound = (f"held {peak:g} N derated to <= {cont * 1.01:.3f} N (continuous {cont:g} N + 1%), never above the "
             f"derated limit, heat never past {spec.thermal_budget_n2s:g} N²·s")
    measured = (f"derated to {final:.3f} N after {derated_at:.1f} s of {_THERMAL_RUN_S:g} s; heat "
                f"{out.heat.heat_n2s:.2f} N²·s; {'HD_WARM_MOTORS' if out.warm else 'no HD_WARM_MOTORS'}")
    # 1e-9 N: the clamp scales the command by limit/|f|, exact to a few ulps
    ok = final <= cont * 1.01 and over_limit <= 1e-9 and not out.warm
    why = "" if ok else "the held force was not derated to the continuous rating within the budget"
    return CheckResult("thermal-budget", "PASS" if ok else "FAIL", measured, bound, why)


def _hold(hardware: str, arm_name: str) -> None:
    """The child of :func:`process_death`: command a force until killed; print one line once it is rendered."""
    from pipeline.assembly.real_rig import open_haptic
    from pipeline.core.clock import MonotonicClock
    from pipeline.settings.hardware import load_hardware

    arm = next(a for a in load_hardware(hardware).arms if a.name == arm_name)
    dev = open_haptic(arm.haptic, MonotonicClock())
    f = _HOLD_FRACTION * float(dev.continuous_force_n)
    period_s = arm.haptic.command_timeout_s / 4  # well inside the device-side watchdog: the command stays fresh
    told = False
    start = time.monotonic()
    while True:
        dev.command_force(0.0, 0.0, f)
        if not told and time.monotonic() - start > 0.1:
            reported = dev.api.current_force()  # type: ignore[attr-defined]  # the Touch's own HDAPI seam
            # a loaded machine may delay a servo tick past the device's watchdog: ask again, for a bounded time
            if _magnitude(reported) >= _HELD_FRACTION * f or time.monotonic() - start > _CHILD_READY_S / 2:
                print(json.dumps({"commanded_n": [0.0, 0.0, f], "reported_n": list(reported)}), flush=True)
                told = True
        time.sleep(period_s)


if __name__ == "__main__":
    _hold(sys.argv[1], sys.argv[2])
