"""Forward fusion: sensor hits become tracks close to the sensors (paper 3, 6.1)."""
from .node import FusionNode

__all__ = ["FusionNode"]
