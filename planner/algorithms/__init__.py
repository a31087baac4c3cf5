"""The registered Speed Planner algorithms (the name is stored with every plan), and the call
that runs one. It lives beside the registry, above the stages the algorithms compose
(`planner.pipeline`), so the stages never import what is built from them."""

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


def plan_speeds(
    inputs: PlannerInputs,
    algorithm: str = "kernel_smooth_buffer",
    params: PlannerParams | None = None,
) -> Plan:
    """Run a registered algorithm; raises NoInrixEstimate when INRIX is missing or stale."""
    return ALGORITHMS.get(algorithm)(inputs, params or PlannerParams())


__all__ = ["ALGORITHMS", "Algorithm", "plan_speeds"]
