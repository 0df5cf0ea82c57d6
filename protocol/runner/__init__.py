"""protocol/runner."""
