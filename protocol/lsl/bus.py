"""The one seam to pylsl: the library (or a one-line refusal saying how to install it), the link between the loop's
clock and LSL's, and the external streams found by name or type.

pylsl is an optional extra (``pip install 'haptic-study[lsl]'``; its wheel bundles liblsl): nothing imports it until
a session asks for LSL, and a machine without it is told so in one line before anything is stored.

**The clocks.**  The loop stamps every tick on its own clock (:class:`pipeline.core.clock.MonotonicClock`,
``time.perf_counter_ns``), and a record's ``t_ns`` counts from the loop's first tick (``loop.t0_ns``).  LSL stamps
on ``local_clock()`` (liblsl's ``steady_clock``).  :func:`measure_link` reads the two clocks alternately and keeps
the pair read closest together: the offset then holds to half that bracket (a microsecond or two), which is
:attr:`ClockLink.uncertainty_s`.  A record's LSL time is ``t_ns * 1e-9 + ClockLink.records_to_lsl_s`` -- the tick's
own time, never the time it was sent.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, cast

from foundation.errors import InputRefused
from protocol.study.lsl_settings import StreamSelector

__all__ = ["ClockLink", "LslUnavailable", "StreamNotFound", "measure_link", "pylsl", "resolve_streams"]

#: How a lab installs what is missing.
INSTALL_HINT = "install it with: pip install 'haptic-study[lsl]' (pylsl's wheel brings liblsl)"


class LslUnavailable(InputRefused):
    """pylsl (or the liblsl it loads) is not on this machine: one line saying how to install it."""


class StreamNotFound(InputRefused):
    """A stream the protocol names was not found on the network within the timeout: one line naming it."""


def pylsl() -> ModuleType:
    """The pylsl module, or :class:`LslUnavailable`."""
    try:
        import pylsl as lib
    except ImportError as exc:  # the package, or its bundled liblsl (RuntimeError is raised as ImportError there)
        raise LslUnavailable(f"LSL: the pylsl library is not available on this machine ({exc}); "
                             f"{INSTALL_HINT}") from None
    except RuntimeError as exc:  # pylsl found no liblsl it can load
        raise LslUnavailable(f"LSL: liblsl could not be loaded ({exc}); {INSTALL_HINT}") from None
    global _configured
    if not _configured:
        _configured = True
        if not any(p.is_file() for p in _config_files()):
            # liblsl's own INFO lines would interleave with the command's output: errors only, unless the lab's
            # lsl_api.cfg says otherwise (its settings are then LSL's, untouched)
            lib.set_config_content(_QUIET_CONFIG)
    return cast(ModuleType, lib)  # (pylsl ships no types)


#: The configuration given to liblsl where the lab has none: its log at warnings and errors only.
_QUIET_CONFIG = "[log]\nlevel = -1\n"
_configured = False


def _config_files() -> list[Path]:
    """Where liblsl looks for its configuration (docs/lsl.md §6): LSLAPICFG, then the working directory, the user's
    and the system's folder."""
    env = os.environ.get("LSLAPICFG")
    return [*([Path(env)] if env else []), Path("lsl_api.cfg"), Path.home() / "lsl_api" / "lsl_api.cfg",
            Path("/etc/lsl_api/lsl_api.cfg")]


@dataclass(frozen=True, slots=True)
class ClockLink:
    """How the loop's records' times map to LSL's clock.

    Attributes
    ----------
    records_to_lsl_s
        LSL time of a record = its ``t_ns`` × 1e-9 + this, s.
    uncertainty_s
        Half the narrowest bracket of the two clocks' readings: the offset's error bound, s.
    """

    records_to_lsl_s: float
    uncertainty_s: float

    def lsl_s(self, t_ns: int) -> float:
        """The LSL time of a record's ``t_ns``."""
        return t_ns * 1e-9 + self.records_to_lsl_s

    def records_ns(self, lsl_s: float) -> float:
        """A record's ``t_ns`` of an LSL time (the inverse of :meth:`lsl_s`)."""
        return (lsl_s - self.records_to_lsl_s) * 1e9


def measure_link(loop_t0_ns: int, local_clock: Callable[[], float], now_ns: Callable[[], int] = time.perf_counter_ns,
                 rounds: int = 200) -> ClockLink:
    """The link between the records' axis (``t_ns`` counts from the loop's first tick at ``loop_t0_ns`` on
    ``now_ns``'s clock) and LSL's ``local_clock``: the pair of readings taken closest together of ``rounds``."""
    best: tuple[int, float] | None = None
    for _ in range(rounds):
        a = now_ns()
        lsl = local_clock()
        b = now_ns()
        if best is None or b - a < best[0]:
            best = (b - a, lsl - (a + b) * 0.5e-9)
    assert best is not None
    bracket_ns, offset_s = best
    return ClockLink(records_to_lsl_s=loop_t0_ns * 1e-9 + offset_s, uncertainty_s=bracket_ns * 0.5e-9)


def resolve_streams(selectors: Sequence[StreamSelector], timeout_s: float, lib: ModuleType | None = None) -> list[Any]:
    """One ``StreamInfo`` per selector, found on the network within ``timeout_s`` each; :class:`StreamNotFound`
    naming the first that was not."""
    lib = lib or pylsl()
    found = []
    for s in selectors:
        infos = lib.resolve_byprop(s.prop, s.value, 1, timeout_s)
        if not infos:
            raise StreamNotFound(f"lsl.record: no LSL stream with {s.words()} was found within {timeout_s:g} s "
                                 "(lsl.resolve_timeout_s); start its outlet, or check the network and lsl_api.cfg "
                                 "(docs/lsl.md); nothing was stored")
        found.append(infos[0])
    return found
