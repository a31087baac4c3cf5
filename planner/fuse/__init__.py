"""Step 2, fusion: the registered variants and the shared interface."""

from planner.fuse.base import Fuser
from planner.fuse.precedence import fuse_precedence
from planner.registry import Registry

FUSERS: Registry[Fuser] = Registry("fuser")
FUSERS.register("precedence", fuse_precedence)

__all__ = ["FUSERS", "Fuser"]
