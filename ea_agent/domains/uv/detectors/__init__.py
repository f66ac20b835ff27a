"""UV detectors, one module per family. Each function takes the UvDomain (`dom`),
the epoch end `t` and the candidate list it appends to; they read the picture the
watchman keeps and the domain's active missions, and run once per epoch."""
from . import collision, handoff, progress, status, targets

__all__ = ["collision", "handoff", "progress", "status", "targets"]
