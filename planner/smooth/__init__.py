"""Step 3, forward kernel smoothing: the registered kernels and the smoother."""

from planner.registry import Registry
from planner.smooth.base import Kernel, forward_kernel_smooth
from planner.smooth.gaussian import gaussian_kernel
from planner.smooth.quartic import quartic_kernel
from planner.smooth.triangular import triangular_kernel
from planner.smooth.uniform import uniform_kernel

KERNELS: Registry[Kernel] = Registry("kernel")
KERNELS.register("uniform", uniform_kernel)
KERNELS.register("gaussian", gaussian_kernel)
KERNELS.register("triangular", triangular_kernel)
KERNELS.register("quartic", quartic_kernel)

__all__ = ["KERNELS", "Kernel", "forward_kernel_smooth"]
