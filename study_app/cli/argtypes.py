"""Argument types of the ``haptic-study`` command line: every number bounded, every error one line.

A bad argument is refused while the command line is parsed -- before any
file or database is touched -- with one line on stderr naming the option, the
value and what is allowed, and exit status 2 (the style of ``CliError``).
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable
from typing import NoReturn

from pipeline.devices.rig import ARM_NAME, ARM_NAME_WHAT
from pipeline.settings.tomlfields import SQLITE_INTEGER_MAX, host_problem

__all__ = [
    "SEED",
    "OneLineParser",
    "add_command",
    "arm_name",
    "arm_names",
    "host_name",
    "one_line",
    "positive_seconds",
    "real_number",
    "setting",
    "setting_list",
    "whole_number",
]


def one_line(text: str) -> str:
    """``text`` with line breaks and other control characters escaped: an error stays on one line."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line (argparse prints the usage line first).

    Subparsers inherit the class (``add_subparsers`` makes parsers of the parent's type).
    """

    def error(self, message: str) -> NoReturn:
        """Print ``<prog>: error: <message>`` on one line and exit with status 2."""
        own = re.match(r"argument (\S+): (\1 = .*)", message, re.DOTALL)
        if own:  # an argument type's own message already names the option, the value and what is allowed
            message = own.group(2)
        else:
            message += f" (see '{self.prog} --help')"
        self.exit(2, f"{self.prog}: error: {one_line(message)}\n")


def whole_number(name: str, lo: int, hi: int, note: str = "") -> Callable[[str], int]:
    """An argument type: an integer from ``lo`` to ``hi`` (``note`` is appended to the error)."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:  # not an integer, or too many digits for Python to read
            v = None
        if v is None or not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: must be a whole number from {lo} to {hi}{note}")
        return v

    return parse


def real_number(name: str, lo: float, hi: float, *, lo_open: bool = False, note: str = "") -> Callable[[str], float]:
    """An argument type: a finite number in ``[lo, hi]``, or ``(lo, hi]`` with ``lo_open``."""

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        if not (math.isfinite(v) and (v > lo if lo_open else v >= lo) and v <= hi):
            rng = f"> {lo:g} and ≤ {hi:g}" if lo_open else f"from {lo:g} to {hi:g}"
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: must be a number {rng}{note}")
        return v

    return parse


def host_name(name: str, *, ipv6: bool = True) -> Callable[[str], str]:
    """An argument type: an IP address or an RFC 1123 host name (the hardware file's rule)."""

    def parse(text: str) -> str:
        problem = host_problem(text, ipv6=ipv6)
        if problem is not None:
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: {problem}")
        return text

    return parse


def arm_name(name: str) -> Callable[[str], str]:
    """An argument type: one arm of a rig, by name (the hardware file's ``[[arm]] name`` rule)."""

    def parse(text: str) -> str:
        if not ARM_NAME.match(text):
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: must be {ARM_NAME_WHAT}")
        return text

    return parse


def arm_names(name: str, most: int = 4) -> Callable[[str], tuple[str, ...]]:
    """An argument type: a rig's arms, comma-separated names (the hardware file's ``[[arm]] name`` rule)."""

    def parse(text: str) -> tuple[str, ...]:
        names = tuple(n.strip() for n in text.split(","))
        bad = next((n for n in names if not ARM_NAME.match(n)), None)
        if bad is not None:
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: each arm must be {ARM_NAME_WHAT}; {bad!r} is not")
        if len(set(names)) != len(names) or len(names) > most:
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: must be 1 to {most} distinct arm names, "
                                             "comma-separated (e.g. left,right)")
        return names

    return parse


def add_command(sub: argparse._SubParsersAction, name: str, help: str, example: str,
                description: str = "") -> argparse.ArgumentParser:
    """A subcommand whose ``--help`` starts with what it does and ends with an example."""
    import shutil
    import textwrap

    width = max(40, min(100, shutil.get_terminal_size().columns - 2))
    return sub.add_parser(
        name, help=help, description=textwrap.fill((description or help[:1].upper() + help[1:]) + ".", width),
        epilog="example:\n  " + "\n  ".join(example.splitlines()),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


#: The shortest simulated or measured time an option may ask for: one tick of the 1 kHz loop, s (less records
#: nothing, and ``sim --seconds 1e-300`` ended in a traceback where the summary found no record: issue 42).
ONE_TICK_S = 0.001


def positive_seconds(name: str, hi: float = 86_400.0) -> Callable[[str], float]:
    """An argument type: a finite number of seconds from one tick (0.001) to ``hi`` (default one day)."""
    return real_number(name, ONE_TICK_S, hi, note=" (one tick of the 1 kHz loop at least)")



def seconds_or_zero(name: str, hi: float, zero: str) -> Callable[[str], float]:
    """An argument type: 0 (``zero`` says what it means) or seconds from one tick (0.001) to ``hi``."""
    seconds = positive_seconds(name, hi)

    def parse(text: str) -> float:
        try:
            if float(text) == 0.0:  # (exactly zero, as typed: "0", "0.0", "-0")
                return 0.0
        except ValueError:
            pass
        try:
            return seconds(text)
        except argparse.ArgumentTypeError:
            allowed = f"0 ({zero}) or a number from {ONE_TICK_S:g} to {hi:g} (one tick of the 1 kHz loop at least)"
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: must be {allowed}") from None

    return parse

#: Seeds are stored in the study database: at most SQLite's largest INTEGER.
SEED = whole_number("--seed", 0, SQLITE_INTEGER_MAX, " (the largest integer SQLite stores)")


def _setting_parts(text: str) -> tuple[str, str]:
    """``NAME=VALUE`` split at its ``=``; the parser's one-line error when there is none."""
    name, eq, value = text.partition("=")
    if not eq or not name.strip():
        raise argparse.ArgumentTypeError(f"--set = {text!r}: must be NAME=VALUE, NAME one of the pipeline's settings "
                                         "(filter_window, f_scale_n, f_max_n, slew_n_per_s, ramp_in_s)")
    return name.strip(), value.strip()


def setting(text: str) -> tuple[str, float]:
    """An argument type: one pipeline setting ``NAME=VALUE`` (:mod:`pipeline.force.pipeline_settings`), checked
    against the pipeline configuration's own limits."""
    from pipeline.force.pipeline_settings import canonical_name, parse_setting

    name, value = _setting_parts(text)
    try:
        if "," in value:
            raise ValueError(f"{canonical_name(name)}: one value here (lists of values are for haptic-study sweep)")
        return canonical_name(name), parse_setting(name, value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--set = {text!r}: {exc}") from None


def setting_list(text: str) -> tuple[str, tuple[float, ...]]:
    """An argument type: ``NAME=V1,V2,...``, the values of one pipeline setting a sweep runs (distinct, each checked
    as :func:`setting` checks one)."""
    from pipeline.force.pipeline_settings import canonical_name, parse_setting

    name, value = _setting_parts(text)
    try:
        key = canonical_name(name)
        texts = [v.strip() for v in value.split(",")]
        if not value or any(not v for v in texts):
            raise ValueError(f"{key}: an empty value; give a comma-separated list of values")
        values = tuple(parse_setting(key, v) for v in texts)
        if len(set(values)) != len(values):
            raise ValueError(f"{key}: a value is given twice; give each value once")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--set = {text!r}: {exc}") from None
    return key, values
