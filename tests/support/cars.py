"""An emulated car whose agent talks to a server as one vehicle of the roster."""

from __future__ import annotations

from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import httpx

from sim.emulator.rig import Rig, rig
from vehicle_agent.server import ServerClient


def car_served_by(
    http: httpx.Client,
    vehicle_id: str,
    token: str,
    tmp_path: Path,
    dbc_cache: Path,
    *,
    make: str = "nissan_rogue",
    timeout_s: float = 3.0,
    **options: Any,
) -> AbstractContextManager[Rig]:
    """The car `vehicle_id` (`make`) with its agent, whose server is `http` and whose
    controller comes from its config; `options` go to `rig` (start, spool, speed, ...)."""
    return rig(
        make,
        tmp_path,
        dbc_cache,
        controller="unused",
        vehicle_id=vehicle_id,
        server=ServerClient(http, vehicle_id, token, timeout_s=timeout_s),
        **options,
    )
