"""Domain modules plug their missions, detectors and VOA heuristics into the core."""
