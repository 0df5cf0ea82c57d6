"""Shared test configuration: the Hypothesis profile, the ``slow`` marker, one analysis worker per test process."""

import os

from hypothesis import settings

# The suite already runs a test per core (xdist), and an xdist worker has threads, so an analysis's own pool
# would be spawned, each process importing pandas and matplotlib again: on 2 cores a report then costs about
# twice its work.  The tests that compare the pools with one process pass their worker counts explicitly.
os.environ.setdefault("HAPTIC_STUDY_WORKERS", "1")

settings.register_profile("ci", max_examples=200, deadline=None)
settings.load_profile("ci")


def pytest_configure(config):
    # A label only: slow tests still run by default (nothing deselects them).
    config.addinivalue_line("markers", "slow: long-running test (runs by default; label only)")


#: The modules that take longest (their fixtures run whole studies, reports or the 228-case command corpus), run
#: first: xdist hands modules out in order (--dist loadfile), so the two workers finish together on small modules
#: instead of one waiting while the other runs a long one (measured: the last ~2 minutes of a run in collection
#: order kept one core idle a quarter of the time).
RUN_FIRST = (
    "tests/test_bad_inputs.py",
    "tests/protocol/test_study.py",
    "tests/protocol/test_one_writer.py",
    "tests/analysis/test_report_cli.py",
    "tests/analysis/test_power_cli.py",
    "tests/analysis/test_replay_cli.py",
    "tests/analysis/test_power.py",
    "tests/protocol/test_damaged_recording.py",
    "tests/test_withdraw.py",
    "tests/analysis/test_power_pool.py",
)


def pytest_collection_modifyitems(config, items):
    rank = {path: i for i, path in enumerate(RUN_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))  # stable: the rest as collected
