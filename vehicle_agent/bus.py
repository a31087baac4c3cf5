"""Opening a CAN bus from a channel spec: `socketcan:can0` in a car, `virtual:<name>` in tests,
the simulator and the demo (python-can's in-process virtual bus)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import can


class BusSpecError(ValueError):
    """The channel spec is not `interface:channel`."""


def parse_channel(spec: str) -> tuple[str, str]:
    """`socketcan:can0` -> ("socketcan", "can0")."""
    interface, sep, channel = spec.partition(":")
    if not sep or not interface or not channel:
        raise BusSpecError(f"CAN channel {spec!r} is not interface:channel, e.g. socketcan:can0")
    return interface, channel


def open_bus(spec: str, filters: Sequence[dict[str, Any]] | None = None) -> can.BusABC:
    """A python-can bus for `spec`, passing only `filters` when given."""
    interface, channel = parse_channel(spec)
    try:
        return can.Bus(interface=interface, channel=channel, can_filters=filters)
    except (can.CanError, OSError, ValueError, ImportError) as error:
        raise BusSpecError(f"cannot open CAN bus {spec}: {error}") from None
