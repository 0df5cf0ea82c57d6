"""Writing a tick's record into a row, compiled: the arm channel's kernel calls it with each field's value under the
field's own name.

:func:`write_record`'s parameters are :data:`pipeline.core.tick_record.RECORD_FIELDS` in order, and each is stored
at its field's index, an integer through the row's ``int64`` view and a measurement through its ``float64`` view
(``tests/pipeline/test_tick_record.py`` reads this function and holds it to the one definition).  Apart from
:mod:`pipeline.core.tick_record` so that reading a recording loads no compiler.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pipeline.core.compiled import State, kernel

__all__ = ["IntRow", "write_record"]

#: A record's row as ``int64`` words (the same memory as its ``float64`` view).
IntRow = npt.NDArray[np.int64]


@kernel
def write_record(rf: State, ri: IntRow, tick: int, t_ns: int, period_ns: int, raw_fx: float, raw_fy: float,
                 raw_fz: float, raw_tx: float, raw_ty: float, raw_tz: float, sensor_age_ns: int, pose_age_ns: int,
                 latency_ns: int, faults: int, haptic_on: int, trial_index: int, phase: int, gain: float,
                 render_fx: float, render_fy: float, render_fz: float, force_n: float, stylus_x_m: float,
                 stylus_y_m: float, stylus_z_m: float, derate: float, t_s: float, comp_fx: float, comp_fy: float,
                 comp_fz: float, filt_fx: float, filt_fy: float, filt_fz: float, tip_fx: float, tip_fy: float,
                 tip_fz: float, base_fx: float, base_fy: float, base_fz: float, haptic_fx: float, haptic_fy: float,
                 haptic_fz: float, scaled_fx: float, scaled_fy: float, scaled_fz: float, tip_x_m: float,
                 tip_y_m: float, tip_z_m: float, true_fx: float, true_fy: float, true_fz: float) -> None:
    """Store one record: every field at its index, through the view of its type."""
    ri[0] = tick
    ri[1] = t_ns
    ri[2] = period_ns
    rf[3] = raw_fx
    rf[4] = raw_fy
    rf[5] = raw_fz
    rf[6] = raw_tx
    rf[7] = raw_ty
    rf[8] = raw_tz
    ri[9] = sensor_age_ns
    ri[10] = pose_age_ns
    ri[11] = latency_ns
    ri[12] = faults
    ri[13] = haptic_on
    ri[14] = trial_index
    ri[15] = phase
    rf[16] = gain
    rf[17] = render_fx
    rf[18] = render_fy
    rf[19] = render_fz
    rf[20] = force_n
    rf[21] = stylus_x_m
    rf[22] = stylus_y_m
    rf[23] = stylus_z_m
    rf[24] = derate
    rf[25] = t_s
    rf[26] = comp_fx
    rf[27] = comp_fy
    rf[28] = comp_fz
    rf[29] = filt_fx
    rf[30] = filt_fy
    rf[31] = filt_fz
    rf[32] = tip_fx
    rf[33] = tip_fy
    rf[34] = tip_fz
    rf[35] = base_fx
    rf[36] = base_fy
    rf[37] = base_fz
    rf[38] = haptic_fx
    rf[39] = haptic_fy
    rf[40] = haptic_fz
    rf[41] = scaled_fx
    rf[42] = scaled_fy
    rf[43] = scaled_fz
    rf[44] = tip_x_m
    rf[45] = tip_y_m
    rf[46] = tip_z_m
    rf[47] = true_fx
    rf[48] = true_fy
    rf[49] = true_fz
