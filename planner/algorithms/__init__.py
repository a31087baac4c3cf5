"""The registered Speed Planner algorithms (the name is stored with every plan)."""

from collections.abc import Callable

from planner.algorithms.kernel_smooth import kernel_smooth
from planner.algorithms.kernel_smooth_buffer import kernel_smooth_buffer
from planner.params import PlannerParams
from planner.pipeline import Plan, PlannerInputs
from planner.registry import Registry

Algorithm = Callable[[PlannerInputs, PlannerParams], Plan]

ALGORITHMS: Registry[Algorithm] = Registry("algorithm")
ALGORITHMS.register("kernel_smooth", kernel_smooth)
ALGORITHMS.register("kernel_smooth_buffer", kernel_smooth_buffer)

__all__ = ["ALGORITHMS", "Algorithm"]
