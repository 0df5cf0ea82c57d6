"""Run a sweep's cells: complete simulated studies per pipeline setting, in parallel, cached (``haptic-study sweep``).

A cell is one setting of the grid in one study ``k``; its participants are the
study's, whatever the setting (:func:`study_number` and
:func:`study_app.headless.sim_trials.participant_seeds` depend on the seed, ``k``
and the participant number only), so every setting meets the same simulated
people.  The participants of all cells still to run go to one process pool (on
the virtual clock); a cell is appended to the cache (:func:`analysis.planning.sweep.append_cell`)
as soon as its last participant is done, so an interrupted sweep loses at most
the cells under way, and cells in the cache are not run again.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from analysis.planning.sim_study import TrialRow, sim_metrics
from analysis.planning.sweep import SweepCell, append_cell, cell_key, protocol_digest, read_cache
from pipeline.force.pipeline_settings import framework_with
from protocol.study.config import ProtocolConfig, default_protocol
from study_app.headless.fanout import run_tasks
from study_app.headless.sim_trials import MODEL_VERSION, SEED_RULE, run_participant

__all__ = ["SweepProgress", "run_sweep", "study_number"]

#: Studies of one seed: study ``k`` of seed ``s`` is study number ``s * STUDIES_PER_SEED + k`` (seed 0's study
#: ``k`` is the calibration bench's study ``k``).
STUDIES_PER_SEED = 1000


def study_number(seed: int, k: int) -> int:
    """The study number (:func:`study_app.headless.sim_trials.participant_seeds`) of a sweep's study ``k``."""
    return seed * STUDIES_PER_SEED + k


@dataclass
class SweepProgress:
    """What the progress display needs."""

    cells_total: int
    cells_cached: int = 0
    cells_done: int = 0
    runs_total: int = 0  # participants still to run, over all cells
    runs_done: int = 0
    elapsed_s: float = 0.0

    @property
    def eta_s(self) -> float:
        """Seconds left at the pace so far (NaN before the first participant is done)."""
        return self.elapsed_s / self.runs_done * (self.runs_total - self.runs_done) if self.runs_done else float("nan")


def _task(args: tuple[int, int, int, dict[str, float], ProtocolConfig]) -> tuple[int, int, list[TrialRow]]:
    cell, study, participant, settings, protocol = args
    return cell, participant, run_participant(study, participant, protocol, framework_with(settings))


def run_sweep(
    grid: Sequence[Mapping[str, float]], *, studies: int, participants: int, seed: int, cache: Path,
    jobs: int = 1, protocol: ProtocolConfig | None = None,
    on_progress: Callable[[SweepProgress], None] | None = None, client: Any = None,
) -> list[SweepCell]:
    """Every cell of ``grid`` × ``studies``: from the cache, or run (and appended to it).

    Parameters
    ----------
    grid
        The settings to run, each a full set of the pipeline's settings by name.
    studies, participants, seed
        Studies per setting, participants per study, and the seed the studies derive from.
    cache
        The cache file (``cells.jsonl`` in the output folder).
    jobs
        Participants run at once, each in a worker process (1: one after the other in this process).
    client
        A Dask client (:func:`study_app.headless.fanout.connect`): the participants run on its cluster instead
        (``jobs`` is then the cluster's business); the cells are cached here as they complete.
    protocol
        The protocol (default: the paper's); its experiment schedule is run.

    Returns
    -------
    list of SweepCell
        In grid order, studies in order within a setting.
    """
    proto = protocol or default_protocol()
    digest = protocol_digest(proto.to_json())
    keys = [(dict(s), k, cell_key(s, k, participants, seed, MODEL_VERSION, digest, SEED_RULE))
            for s in grid for k in range(studies)]
    have = read_cache(cache, sim_metrics(proto.task))
    todo = [i for i, (_, _, key) in enumerate(keys) if key not in have]
    progress = SweepProgress(cells_total=len(keys), cells_cached=len(keys) - len(todo),
                             runs_total=len(todo) * participants)
    tasks = [(i, study_number(seed, keys[i][1]), j, keys[i][0], proto)
             for i in todo for j in range(1, participants + 1)]
    parts: dict[int, dict[int, list[TrialRow]]] = {i: {} for i in todo}
    t0 = time.monotonic()

    def done(result: tuple[int, int, list[TrialRow]]) -> None:
        i, j, rows = result
        parts[i][j] = rows
        progress.runs_done += 1
        if len(parts[i]) == participants:
            rows_i = [r for n in sorted(parts[i]) for r in parts[i][n]]
            append_cell(cache, keys[i][2], rows_i)
            have[keys[i][2]] = rows_i
            progress.cells_done += 1
        progress.elapsed_s = time.monotonic() - t0
        if on_progress is not None:
            on_progress(progress)

    if on_progress is not None:
        on_progress(progress)
    run_tasks(_task, tasks, done, jobs=jobs, client=client, name="haptic-study-sweep")
    return [SweepCell(s, k, have[key]) for s, k, key in keys]
