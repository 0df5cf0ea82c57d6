"""protocol/study."""
