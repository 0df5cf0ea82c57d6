"""analysis/planning."""
