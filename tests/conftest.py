"""Shared test configuration: the Hypothesis profile and the ``slow`` marker."""

from hypothesis import settings

settings.register_profile("ci", max_examples=200, deadline=None)
settings.load_profile("ci")


def pytest_configure(config):
    # A label only: slow tests still run by default (nothing deselects them).
    config.addinivalue_line("markers", "slow: long-running test (runs by default; label only)")
