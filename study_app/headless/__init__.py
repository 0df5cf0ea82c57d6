"""The headless study runner (``haptic-study run``): simulated participants on the simulated rig, in parallel.

The top floor beside the GUI's engine: both open sessions through
:mod:`protocol.runner.session_setup`; this package adds the simulated rig and
participant, the virtual-clock driver, the worker pool and the planning of a
``run`` (new, ``--continue``, ``--resume``) before anything is written.
"""

from protocol.runner.session_setup import participant_code
from study_app.headless.plan import check_fault_plans
from study_app.headless.pool import StudyWorkerError, default_jobs
from study_app.headless.session_run import SessionInterrupted, StudyProgress, planned_study_time_s
from study_app.headless.study import resume_session, run_study

__all__ = [
    "SessionInterrupted", "StudyProgress", "StudyWorkerError", "check_fault_plans", "default_jobs", "participant_code",
    "planned_study_time_s", "resume_session", "run_study",
]
