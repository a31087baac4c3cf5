"""Step 4, bottleneck identification: the registered finders and the standing test."""

from planner.bottlenecks.base import BottleneckFinder, standing_bottlenecks
from planner.bottlenecks.speed_rise import find_speed_rise
from planner.registry import Registry

FINDERS: Registry[BottleneckFinder] = Registry("bottleneck finder")
FINDERS.register("speed_rise", find_speed_rise)

__all__ = ["FINDERS", "BottleneckFinder", "standing_bottlenecks"]
