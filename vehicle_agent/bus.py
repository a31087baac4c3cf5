"""Opening a CAN bus from a channel spec: `socketcan:can0` in a car, `virtual:<name>` in tests,
the simulator and the demo (python-can's in-process virtual bus). A car whose frames are CAN-FD
(the 2023 Rogue) needs the channel opened for CAN-FD: on socketcan a classic socket never
receives an FD frame."""

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


# Interfaces that filter in the kernel or the adapter. Elsewhere python-can filters in software,
# and then `recv(timeout=0)` can answer None while frames are still queued (it gives up after
# the first filtered-out frame), which would starve the agent's drain loop: there the agent gets
# every frame and ignores the ids it does not watch itself.
FILTERING_INTERFACES = frozenset({"socketcan"})


def open_bus(
    spec: str, filters: Sequence[dict[str, Any]] | None = None, *, fd: bool = False
) -> can.BusABC:
    """A python-can bus for `spec`, passing only `filters` where the interface filters, and
    open for CAN-FD frames when `fd`."""
    interface, channel = parse_channel(spec)
    if interface not in FILTERING_INTERFACES:
        filters = None
    try:
        return can.Bus(interface=interface, channel=channel, can_filters=filters, fd=fd)
    except (can.CanError, OSError, ValueError, ImportError) as error:
        raise BusSpecError(f"cannot open CAN bus {spec}: {error}") from None
