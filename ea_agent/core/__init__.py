"""Domain-independent EA framework: facts, timed monitors, VOA, the manager loop."""
