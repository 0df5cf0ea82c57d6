"""pipeline/assembly."""
