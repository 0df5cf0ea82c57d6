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

