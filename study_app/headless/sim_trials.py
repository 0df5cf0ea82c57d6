"""Simulated participants through the experiment's schedule without a database (the sweep's and the bench's runner).

:func:`run_participant` builds the simulated rig on the virtual clock with the
given pipeline configuration, hands the stylus to a
:class:`pipeline.sim.participant.SimulatedParticipant` and walks the protocol's
experiment schedule through the real :class:`protocol.study.trial.TrialMachine` over the protocol's task
(:mod:`protocol.tasks`), so success, TCT, RMSE and Max AE come from the one definition, and the participant aims at
what the task says.  Nothing is stored: it is ``haptic-study run``'s
experiment session less the recording, training and resumption, about 2 s of
wall clock per participant.

Seeds depend on the study number and the participant number only
(:func:`participant_seeds`), never on the pipeline's settings: the same
participants meet every setting of a sweep, so the comparison is paired.  They are ``haptic-study run``'s
(:func:`protocol.runner.session_setup.participant_seeds`, the study number as the study seed): participant j of
study k here is participant j of ``run --seed k``, the same person on the same rig through the same schedule (issue
48: the calibration's two paths met different participants and so disagreed; checked trial by trial in
tests/test_sweep.py).
"""

from __future__ import annotations

from typing import Any

from analysis.planning.sim_study import TrialRow, sim_metrics
from pipeline.assembly.engine import EngineConfig, build_sim_engine
from pipeline.assembly.sim_config import sim_rig_config
from pipeline.force.config import FrameworkConfig
from pipeline.runtime.loop_messages import AllowBiasRefinement, Mark, SetHaptics
from pipeline.sim.participant import SimulatedParticipant
from pipeline.sim.participant_params import MODEL_FIT, MODEL_VERSION
from protocol.runner.session_setup import participant_seeds as run_seeds
from protocol.study.config import ProtocolConfig, default_protocol
from protocol.study.design import build_schedule
from protocol.study.trial import PhaseChanged, TrialFinished, TrialMachine, TrialPhase
from study_app.headless.fanout import run_tasks

__all__ = ["MODEL_FIT", "MODEL_VERSION", "SEED_RULE", "participant_seeds", "run_participant", "run_study"]

#: How :func:`participant_seeds` draws the participants (part of a sweep cell's key: the rule before issue 48
#: met other people for the same study number).
SEED_RULE = "run"
#: Ticks per step of the loop between reads of the ring.
_BLOCK_TICKS = 20
#: The ring's phase marks (as the session runner writes them).
_PHASE_ACTIVE = 2
_PHASE_PAUSE = 3


def participant_seeds(study: int, participant: int) -> tuple[int, int, int]:
    """(rig seed, participant seed, schedule seed) of participant ``participant`` (1-based) of ``study``: those of
    ``haptic-study run --seed study``'s participant of that number (its experiment session's rig)."""
    rig_seed, p_seed = run_seeds(study, participant)
    return rig_seed, p_seed, study


def run_participant(study: int, participant: int, protocol: ProtocolConfig | None = None,
                    framework: FrameworkConfig | None = None, profile: str = "novice") -> list[TrialRow]:
    """Run one simulated participant through the experiment's schedule; return the trial rows.

    Parameters
    ----------
    study, participant
        Study number (≥ 0) and participant number (≥ 1): they alone fix the seeds.
    protocol
        The protocol (default: the paper's); its experiment schedule is run, no training.
    framework
        The pipeline's configuration (default: the paper's).
    profile
        The simulated participant's profile (:mod:`pipeline.sim.experience`): ``novice`` or ``experienced``.
    """
    proto = protocol or default_protocol()
    rig_seed, p_seed, sched_seed = participant_seeds(study, participant)
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold", sim=sim_rig_config(rig_seed),
                                        framework=framework or FrameworkConfig()))
    loop, ring = eng.loop, eng.ring
    assert ring is not None
    p = SimulatedParticipant(seed=p_seed, tissue=eng.rig.config.tissue, arm=eng.rig.config.arm,
                             motion_scale=eng.rig.config.motion_scale, profile=profile)
    eng.rig.set_driver(p)
    task = proto.task
    carried = sim_metrics(task)
    machine = TrialMachine(proto.trial, task)
    loop.submit(SetHaptics(False))
    loop.run_ticks(200)  # settle on the start pose
    cursor = ring.write_count
    rows: list[TrialRow] = []
    for spec in build_schedule(proto, sched_seed, participant):
        on = spec.haptic_mode == "on"
        machine.start(spec, eng.clock.now_ns())
        loop.submit(AllowBiasRefinement(False))
        loop.submit(SetHaptics(on))
        loop.submit(Mark(spec.index, _PHASE_ACTIVE))
        p.begin_trial(task.aim(spec, aid=False), eng.rig.sim_time_s)
        idle = False
        while not idle:
            loop.run_ticks(_BLOCK_TICKS)
            res = ring.read_since(cursor)
            cursor = res.cursor
            r = res.rows
            t_ns = [int(round(x * 1e9)) for x in r["t_s"].tolist()]
            samples = zip(t_ns, r["force_n"].tolist(), [int(x) for x in r["trial_index"].tolist()], strict=True)
            for ev in machine.feed(samples):
                if isinstance(ev, TrialFinished):
                    rows.append(TrialRow(study, participant, spec.index, spec.target_label, spec.haptic_mode,
                                         {m.name: ev.metrics[m.name] for m in carried}))
                    p.end_trial(eng.rig.sim_time_s)
                    loop.submit(Mark(-1, _PHASE_PAUSE))
                    loop.submit(SetHaptics(False))
                    loop.submit(AllowBiasRefinement(True))
                elif isinstance(ev, PhaseChanged) and ev.new is TrialPhase.IDLE:
                    idle = True
    eng.rig.close()
    ring.close()
    return rows


def _run_participant_args(args: tuple[int, int]) -> list[TrialRow]:
    return run_participant(*args)


def run_study(study: int, participants: int = 10, jobs: int = 1, client: Any = None) -> list[TrialRow]:
    """All participants of one study at the paper's settings, in participant order (``jobs`` > 1: a process per
    participant; ``client``: on its Dask cluster, :mod:`study_app.headless.fanout`)."""
    parts: dict[int, list[TrialRow]] = {}

    def keep(rows: list[TrialRow]) -> None:
        if rows:
            parts[rows[0].participant] = rows

    run_tasks(_run_participant_args, [(study, j) for j in range(1, participants + 1)], keep, jobs=jobs,
              client=client, name="haptic-study-calibration")
    return [r for j in sorted(parts) for r in parts[j]]
