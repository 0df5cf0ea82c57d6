"""``haptic-study gui``: the experimenter's window.

Qt is imported by the command only: the other subcommands, and ``--help``,
never load it.
"""

from __future__ import annotations

import argparse
import os

from study_app.argtypes import add_command, real_number
from study_app.cli_error import CliError

__all__ = ["add_gui_parser", "cmd_gui"]


def add_gui_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register ``gui``."""
    g = add_command(sub, "gui", "the experimenter's window (simulated rig by default)",
                    "haptic-study gui --db study.db\n"
                    "haptic-study gui --rig real --hardware hardware.toml --db study.db\n"
                    "haptic-study gui --screenshot docs/screenshots   # regenerate the guide's screenshots",
                    "Open the experimenter's window: session setup, live force, trial table, device health, the "
                    "participant screen and the calibration wizard (simulated rig by default; see docs/gui.md)")
    g.add_argument("--db", default=None, metavar="PATH", help="study database (SQLite); default: the last one used")
    g.add_argument("--rig", choices=("sim", "real"), default="sim", help="simulated rig (default) or the real hardware")
    g.add_argument("--hardware", default=None, metavar="FILE", help="hardware.toml for --rig real")
    g.add_argument("--screenshot", default=None, metavar="DIR",
                   help="drive a short simulated session offscreen and save PNGs of every main view into DIR")
    g.add_argument("--sim-mount-error-deg", type=real_number("--sim-mount-error-deg", -180.0, 180.0), default=0.0,
                   metavar="DEG", help="simulated rig: mount the sensor turned about its own z axis by DEG without "
                                       "telling the pipeline (rehearse the wizard's frame check failing)")
    g.set_defaults(handler=cmd_gui)


def cmd_gui(args: argparse.Namespace) -> int:
    """Run ``haptic-study gui``: checks first (one line, exit 2), then Qt is loaded and the window opens."""
    from study_app.engine_setup import HostConfig

    if args.rig == "real" and args.hardware is None:
        raise CliError("--rig real needs --hardware FILE (the hardware.toml of the lab; see hardware.example.toml)")
    if args.hardware is not None and not os.path.isfile(args.hardware):
        raise CliError(f"--hardware = {args.hardware!r}: no such file")
    if args.rig == "real":
        # validated here, before any window opens: a bad field is one line and exit 2
        from pipeline.hardware import HardwareError, load_hardware

        try:
            load_hardware(args.hardware)
        except HardwareError as exc:
            raise CliError(str(exc)) from None
    if args.screenshot is not None and args.rig != "sim":
        raise CliError("--screenshot runs on the simulated rig only (omit --rig real)")
    if args.sim_mount_error_deg and args.rig != "sim":
        raise CliError("--sim-mount-error-deg applies to the simulated rig only (omit it with --rig real)")
    if args.screenshot is None and not any(os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")):
        # without this Qt aborts the process with a core dump and a page of plugin names
        raise CliError(
            "no display to open the window on (DISPLAY and WAYLAND_DISPLAY are unset): run it on the lab PC's "
            "desktop, or pass --screenshot DIR to drive it offscreen"
        )
    # Qt is imported here only: the other subcommands never load it
    from study_app.gui.app import run_gui

    if args.screenshot is not None:
        # a rehearsal on the virtual clock at 4x real time: a few trials in seconds
        host = HostConfig(rig="sim", clock="virtual", speed=4.0)
    else:
        host = HostConfig(rig=args.rig, hardware_path=args.hardware, clock="real",
                          sim_mount_error_deg=args.sim_mount_error_deg)
    try:
        return run_gui(host, db_path=args.db, screenshot_dir=args.screenshot)
    except RuntimeError as exc:
        raise CliError(str(exc)) from None
