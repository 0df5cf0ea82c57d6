"""``haptic-study probe netft`` and ``haptic-study check-hardware``: talk to the real devices.

Every wait is bounded by a timeout; an unreachable device is one clear line
and a non-zero exit, never a hang.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from typing import Any

from study_app.cli.argtypes import add_command, arm_name, host_name, whole_number
from study_app.cli.error import CliError
from study_app.guide_paths import hardware_template


class HardwareCmdError(Exception):
    """A user-facing error of these commands (the CLI turns it into one line, exit 2)."""


def probe_netft(
    host: str, port: int = 49152, http_port: int = 80, samples: int = 1000, timeout_s: float = 5.0,
    connect_timeout_s: float = 2.0,
) -> dict[str, Any]:
    """Read ``samples`` fresh records; mean wrench (N, N·m), packet rate and counters as plain data."""
    from pipeline.backends.netft import NetFTError, NetFTForceSensor

    try:
        sensor = NetFTForceSensor(host, port=port, http_port=http_port, connect_timeout_s=connect_timeout_s)
    except NetFTError as exc:
        raise HardwareCmdError(str(exc)) from None
    try:
        t0 = time.perf_counter()
        got = sensor.collect(samples, timeout_s)
        elapsed = time.perf_counter() - t0
    finally:
        sensor.close()
    if not got:
        raise HardwareCmdError(f"the Net F/T at {host}:{port} stopped sending within {timeout_s:g} s")
    n = len(got)
    mean = [math.fsum(s[i] for s in got) / n for i in range(1, 7)]
    cal = sensor.calibration
    return {
        "host": host, "port": port, "samples": n, "requested": samples, "seconds": elapsed,
        "rate_hz": n / elapsed if elapsed > 0 else math.nan,
        "mean_force_n": mean[:3], "mean_torque_nm": mean[3:],
        "calibration": {"counts_per_force": cal.counts_per_force, "counts_per_torque": cal.counts_per_torque,
                        "force_unit": cal.force_unit, "torque_unit": cal.torque_unit, "source": cal.source},
        **{k: v for k, v in sensor.stats.as_dict().items() if k != "last_error"},
    }


def format_probe(r: dict[str, Any]) -> str:
    """The probe result as a few human-readable lines."""
    f, t = r["mean_force_n"], r["mean_torque_nm"]
    lines = [
        f"Net F/T {r['host']}:{r['port']}: {r['samples']} samples in {r['seconds']:.3f} s ({r['rate_hz']:.0f} Hz)"
        + ("" if r["samples"] == r["requested"] else f" -- asked for {r['requested']}"),
        f"  mean force   {f[0]:+9.4f} {f[1]:+9.4f} {f[2]:+9.4f} N",
        f"  mean torque  {t[0]:+9.5f} {t[1]:+9.5f} {t[2]:+9.5f} N·m",
        f"  lost {r['lost']}, reordered {r['reordered']}, duplicate {r['duplicate']}, corrupt {r['corrupt']}, "
        f"stalled {r['stalled']}, bad status {r['bad_status']} (last status 0x{r['last_status']:08x})",
        f"  counts per unit {r['calibration']['counts_per_force']:g} / {r['calibration']['counts_per_torque']:g} "
        f"({r['calibration']['force_unit']}, {r['calibration']['torque_unit']}) from {r['calibration']['source']}",
    ]
    return "\n".join(lines)


def check_hardware(path: str, arm: str | None = None) -> tuple[list[tuple[str, bool, str]], bool]:
    """Open each configured device in turn, describe it, close it; ``(rows, all_ok)``.

    ``arm`` names the one arm to check; None checks every arm in turn (the rows of a rig of several arms start
    with the arm's name).

    Raises
    ------
    HardwareCmdError
        When the hardware file itself is invalid.
    CliError
        ``arm`` names no arm of the file.
    """
    from pipeline.core.clock import MonotonicClock
    from pipeline.settings.hardware import HardwareError, load_hardware
    from study_app.cli.calibrate_cmds import chosen_arm

    try:
        hw = load_hardware(path)
    except HardwareError as exc:
        raise HardwareCmdError(str(exc)) from None
    names = tuple(a.name for a in hw.arms)
    one = chosen_arm(names, arm, path, required=False)
    clock = MonotonicClock()
    rows: list[tuple[str, bool, str]] = []
    for a in hw.arms:
        if one is None or a.name == one:
            _check_arm(a, clock, rows, f"{a.name}: " if len(names) > 1 else "")
    return rows, all(ok for _, ok, _ in rows)


def _check_arm(hw: Any, clock: Any, rows: list[tuple[str, bool, str]], prefix: str) -> None:
    """Open, describe and close each device of the arm ``hw`` (:class:`pipeline.settings.hardware.ArmSettings`),
    a row each, named after ``prefix``."""
    from pipeline.assembly.real_rig import open_haptic, open_jaw, open_robot, open_sensor
    from pipeline.devices.interfaces import DeviceError

    def attempt(name: str, opener: Any, describe: Any) -> None:
        name = prefix + name
        try:
            dev = opener()
        except (DeviceError, OSError, ValueError) as exc:
            rows.append((name, False, str(exc)))
            return
        try:
            rows.append((name, True, describe(dev)))
        finally:
            try:
                dev.close()
            except Exception:  # the description is what matters here
                pass

    def describe_sensor(s: Any) -> str:
        got = s.collect(100, 2.0)
        w = s.read_wrench()
        rate = f"{len(got)} fresh samples" if len(got) < 100 else "streaming"
        text = (f"{hw.sensor.host}: {rate}, F = ({w.fx:+.3f}, {w.fy:+.3f}, {w.fz:+.3f}) N, status 0x{w.status:08x}, "
                f"lost {s.stats.lost}, cpf {s.calibration.counts_per_force:g} from {s.calibration.source}")
        rdt = s.calibration.rdt_rate_hz
        if 0 < rdt < 1000:
            # the watchdog calls a sample older than 5 ms stale: the box must stream at ≥ 1 kHz
            text += f"; WARNING: RDT rate {rdt:g} Hz < 1000 Hz, set it on the box's web page"
        return text

    def describe_robot(r: Any) -> str:
        from pipeline.backends.ur import ur3_tcp_pose

        p = r.read_pose()
        fk, _ = ur3_tcp_pose(r.q_rad, hw.robot.tcp_offset_m)
        dist = math.dist(fk, p.position_m) if all(math.isfinite(v) for v in (*fk, *p.position_m)) else math.nan
        return (f"{hw.robot.host}: {r.state}, TCP ({p.position_m[0]:+.4f}, {p.position_m[1]:+.4f}, "
                f"{p.position_m[2]:+.4f}) m, controller time {p.controller_time_s:.3f} s, UR3 DH FK differs by "
                f"{dist * 1000:.1f} mm")

    def describe_haptic(h: Any) -> str:
        st = h.read_state()
        return (f"{hw.haptic.device_name}: peak {h.peak_force_n:g} N, continuous {h.continuous_force_n:g} N, "
                f"error 0x{st.error_code:04x}")

    def describe_jaw(j: Any) -> str:
        s = j.status
        return (f"{hw.jaw.port if hw.jaw else ''}: READY, limits {s.closed_us}-{s.open_us} µs, at {s.pos_us} µs "
                f"({s.fraction_open:.0%} open)")

    attempt("force sensor", lambda: open_sensor(hw.sensor, clock), describe_sensor)
    attempt("robot", lambda: open_robot(hw.robot, clock), describe_robot)
    attempt("haptic device", lambda: open_haptic(hw.haptic, clock), describe_haptic)
    if hw.jaw is not None:
        jaw_cfg = hw.jaw
        attempt("jaw actuator", lambda: open_jaw(jaw_cfg), describe_jaw)
    from study_app.cli.qualify_cmds import describe_record

    # the record is shown, not judged here: only a failed qualification or an unreadable record makes the row FAIL
    qualified = describe_record(hw.calibration_file)
    rows.append((prefix + "qualification", qualified is None or qualified.startswith(("PASS", "PARTIAL")),
                 qualified or "never qualified (haptic-study qualify)"))


def format_check(rows: list[tuple[str, bool, str]]) -> str:
    """One line per device."""
    width = max([14, *(len(name) for name, _, _ in rows)])
    return "\n".join(f"{name:<{width}} {'OK  ' if ok else 'FAIL'} {text}" for name, ok, text in rows)


def to_json(obj: Any) -> str:
    """JSON with NaN kept readable."""
    return json.dumps(obj)


# -- the command line -------------------------------------------------------------------------------------
def _port_number(name: str) -> Callable[[str], int]:
    """An argument type: a TCP/UDP port."""
    return whole_number(name, 1, 65535)


def add_probe_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``probe`` and its devices."""
    pr = add_command(sub, "probe", "read a real device once and report (no loop)",
                     "haptic-study probe netft --host 192.168.1.1 --samples 1000")
    prsub = pr.add_subparsers(dest="probe", metavar="DEVICE")
    prsub.required = True
    pn = add_command(prsub, "netft", "ATI Net F/T: mean wrench (N, N·m), packet rate, lost/reordered/faulted counts",
                     "haptic-study probe netft --host 192.168.1.1 --samples 1000")
    pn.add_argument("--host", required=True, type=host_name("--host", ipv6=False), help="the Net F/T box's IP address")
    pn.add_argument("--port", type=_port_number("--port"), default=49152, help="RDT UDP port (default 49152)")
    pn.add_argument("--http-port", type=_port_number("--http-port"), default=80,
                    help="web server port for netftapi2.xml (default 80)")
    pn.add_argument("--samples", type=whole_number("--samples", 1, 1_000_000), default=1000,
                    help="samples to average (default 1000)")
    pn.add_argument("--json", action="store_true", help="print one JSON object")
    pn.set_defaults(handler=cmd_hardware)


def add_check_hardware_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``check-hardware``."""
    ch = add_command(sub, "check-hardware", "connect to every device in the hardware file and print its state",
                     "haptic-study check-hardware --hardware hardware.toml")
    ch.add_argument("--hardware", default="hardware.toml", metavar="FILE",
                    help=f"hardware file (default ./hardware.toml; see {hardware_template()})")
    ch.add_argument("--arm", type=arm_name("--arm"), default=None, metavar="NAME",
                    help="a rig of several arms: check this arm's devices only (default: every arm in turn)")
    ch.set_defaults(handler=cmd_hardware)


def cmd_hardware(args: argparse.Namespace) -> int:
    """Run ``haptic-study probe netft`` or ``check-hardware``; errors raise :class:`CliError`."""
    try:
        if args.command == "probe":
            result = probe_netft(args.host, args.port, args.http_port, args.samples)
            print(json.dumps(result) if args.json else format_probe(result))
            return 0
        rows, ok = check_hardware(args.hardware, args.arm)
    except HardwareCmdError as exc:
        raise CliError(str(exc)) from None
    print(format_check(rows))
    return 0 if ok else 1
