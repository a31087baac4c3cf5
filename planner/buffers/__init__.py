"""Step 5, buffer design: the registered designers and how their ceilings become targets."""

from planner.buffers.base import Buffer, BufferDesign, BufferDesigner, apply_buffers
from planner.buffers.queue_storage import design_queue_storage
from planner.registry import Registry

DESIGNERS: Registry[BufferDesigner] = Registry("buffer designer")
DESIGNERS.register("queue_storage", design_queue_storage)

__all__ = ["DESIGNERS", "Buffer", "BufferDesign", "BufferDesigner", "apply_buffers"]
