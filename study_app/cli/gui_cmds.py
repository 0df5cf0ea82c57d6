"""``haptic-study gui``: the experimenter's window.

Qt is imported by the command only: the other subcommands, and ``--help``,
never load it.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from foundation.errors import InputRefused
from pipeline.devices.rig import SINGLE_ARM_NAME
from study_app.cli.argtypes import add_command, arm_names, real_number, setting
from study_app.cli.error import CliError
from study_app.guide_paths import guide, hardware_template

__all__ = ["SCREENSHOT_MARKER", "add_gui_parser", "cmd_gui"]

#: The marker of a screenshot folder (foundation.outdir): the PNGs ``gui --screenshot`` wrote, with their SHA-256.
SCREENSHOT_MARKER = ".haptic-study-screenshots"


def add_gui_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``gui``."""
    g = add_command(sub, "gui", "the experimenter's window (simulated rig by default)",
                    "haptic-study gui --db study.db\n"
                    "haptic-study gui --rig real --hardware hardware.toml --db study.db\n"
                    "haptic-study gui --screenshot shots   # the guide's screenshots, into a new folder shots/",
                    "Open the experimenter's window: session setup, live force, trial table, device health, the "
                    f"participant screen and the calibration wizard (simulated rig by default; see {guide('gui.md')})")
    g.add_argument("--db", default=None, metavar="PATH", help="study database (SQLite); default: the last one used")
    g.add_argument("--rig", choices=("sim", "real"), default="sim", help="simulated rig (default) or the real hardware")
    g.add_argument("--hardware", default=None, metavar="FILE", help="hardware.toml for --rig real")
    g.add_argument("--screenshot", default=None, metavar="DIR",
                   help="drive a short simulated session offscreen and save PNGs of every main view into DIR (new or "
                        "empty, unless --force)")
    g.add_argument("--force", action="store_true",
                   help="with --screenshot: replace the PNGs an earlier --screenshot wrote in DIR, if unedited (the "
                        "marker .haptic-study-screenshots lists them with their SHA-256); any other file is a refusal")
    g.add_argument("--sim-mount-error-deg", type=real_number("--sim-mount-error-deg", -180.0, 180.0), default=0.0,
                   metavar="DEG", help="simulated rig: mount the sensor turned about its own z axis by DEG without "
                                       "telling the pipeline (rehearse the wizard's frame check failing)")
    g.add_argument("--set", dest="settings", action="append", default=[], type=setting, metavar="NAME=VALUE",
                   help="simulated rig: a pipeline setting of its sessions, as run --set (filter_window, f_scale_n, "
                        "f_max_n, slew_n_per_s, ramp_in_s); repeatable")
    g.add_argument("--sim-arms", dest="sim_arms", type=arm_names("--sim-arms"), default=(SINGLE_ARM_NAME,),
                   metavar="NAMES",
                   help=f"simulated rig: its arms, comma-separated, in any order (default: one arm, "
                        f"{SINGLE_ARM_NAME}); Start puts the protocol's task arm (design.task_arm) first, restarting "
                        "the simulated rig if needed, as run --sim-arms does; a session records every arm")
    g.add_argument("--lsl", action="store_true",
                   help="publish every session's force streams and trial markers on the Lab Streaming Layer (as the "
                        "protocol's [lsl] outlets = true; needs pylsl: docs/lsl.md)")
    g.set_defaults(handler=cmd_gui)


def cmd_gui(args: argparse.Namespace) -> int:
    """Run ``haptic-study gui``: checks first (one line, exit 2), then Qt is loaded and the window opens."""
    if args.rig == "real" and args.hardware is None:
        raise CliError(f"--rig real needs --hardware FILE (the hardware.toml of the lab; see {hardware_template()})")
    if args.hardware is not None and not os.path.isfile(args.hardware):
        raise CliError(f"--hardware = {args.hardware!r}: no such file")
    if args.rig == "real":
        # validated here, before any window opens: a bad field is one line and exit 2
        from pipeline.settings.hardware import HardwareError, load_hardware

        try:
            load_hardware(args.hardware)
        except HardwareError as exc:
            raise CliError(str(exc)) from None
    if args.force and args.screenshot is None:
        raise CliError("--force applies to --screenshot DIR only (the window writes no folder)")
    if args.screenshot is not None and args.rig != "sim":
        raise CliError("--screenshot runs on the simulated rig only (omit --rig real)")
    if args.sim_mount_error_deg and args.rig != "sim":
        raise CliError("--sim-mount-error-deg applies to the simulated rig only (omit it with --rig real)")
    if args.sim_arms != (SINGLE_ARM_NAME,) and args.rig != "sim":
        raise CliError("--sim-arms applies to the simulated rig only (the real rig's arms are its hardware file's)")
    if args.settings and args.rig != "sim":
        raise CliError("--set applies to the simulated rig only (the real rig's pipeline is its hardware file's)")
    from pipeline.force.pipeline_settings import non_default_settings, settings_of
    from study_app.cli.run_cmds import framework_of

    sim_settings = tuple(non_default_settings(settings_of(framework_of(args.settings))).items())
    if args.screenshot is None and not any(os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY",
                                                                       "QT_QPA_PLATFORM")):
        # without this Qt aborts the process with a core dump and a page of plugin names
        raise CliError(
            "no display to open the window on (DISPLAY and WAYLAND_DISPLAY are unset): run it on the lab PC's "
            "desktop, or pass --screenshot DIR to drive it offscreen"
        )
    if args.screenshot is not None:
        return _screenshots(args)
    # Qt is imported here only: the other subcommands never load it
    from study_app.engine.setup import HostConfig
    from study_app.gui.app import run_gui

    host = HostConfig(rig=args.rig, hardware_path=args.hardware, clock="real",
                      sim_mount_error_deg=args.sim_mount_error_deg, sim_settings=sim_settings,
                      sim_arms=args.sim_arms, lsl=args.lsl)
    if args.lsl:
        from protocol.lsl.bus import pylsl

        pylsl()  # (missing: one line saying how to install it, before the window opens)
    try:
        return run_gui(host, db_path=args.db)
    except RuntimeError as exc:
        raise CliError(str(exc)) from None


def _screenshots(args: argparse.Namespace) -> int:
    """``gui --screenshot DIR``: the tour's PNGs, written under the output policy (:mod:`foundation.outdir`)."""
    from foundation.outdir import check_output_folder, write_output_folder

    folder: dict[str, Any] = {"command": "gui --screenshot", "marker": SCREENSHOT_MARKER, "force": args.force,
                              "option": "--screenshot",
                              "inputs": [args.db] if args.db else []}
    status = 0

    def tour(tmp: Path) -> None:
        nonlocal status
        from study_app.engine.setup import HostConfig
        from study_app.gui.app import run_gui  # Qt is imported here only

        # a rehearsal on the virtual clock at 4x real time: a few trials in seconds
        status = run_gui(HostConfig(rig="sim", clock="virtual", speed=4.0), db_path=args.db,
                         screenshot_dir=str(tmp))

    try:
        check_output_folder(args.screenshot, **folder)  # before the window opens
        files = write_output_folder(args.screenshot, tour, **folder)
    except InputRefused as exc:
        raise CliError(str(exc), getattr(exc, "status", 2)) from None
    except RuntimeError as exc:
        raise CliError(str(exc), 1) from None
    for name in files:
        print(f"wrote {Path(args.screenshot) / name}")
    return status
