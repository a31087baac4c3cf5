"""Vehicle data for tests, written as the API's pings and status reports.

Tests describe a drive by position along the corridor (x_m) because hand-worked values (Edie
boxes, plan segments) are about positions; `ping()` turns that into the GPS fix a car would send,
so the server's own map-matching puts it back at x_m.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from functools import lru_cache
from typing import Any

from sqlalchemy import Connection, insert

from app.models import VehiclePing
from app.seed import seed_corridor_document
from vehicle_agent.corridor import CorridorGeometry

CORRIDOR = "I-24-WB"


@lru_cache(maxsize=1)
def seed_geometry() -> CorridorGeometry:
    """The seed corridor's reference line."""
    document = seed_corridor_document()
    return CorridorGeometry.from_segments(
        CORRIDOR, document["corridor"]["lanes"], document["i24_segments"]
    )


def ping(
    vehicle_id: str, ts: datetime, x_m: float, speed_mps: float, **fields: Any
) -> dict[str, Any]:
    """A ping payload at corridor position x_m (optional API fields passed through)."""
    lat, lon = seed_geometry().position(x_m)
    return {
        "vehicle_id": vehicle_id,
        "ts": ts.isoformat(),
        "lat": float(lat),
        "lon": float(lon),
        "speed_mps": speed_mps,
        **fields,
    }


def drive(
    vehicle_id: str,
    start: datetime,
    x0_m: float,
    speed_mps: float,
    seconds: int,
    **fields: Any,
) -> list[dict[str, Any]]:
    """1 Hz pings of a vehicle holding a constant speed from x0_m for `seconds` pings."""
    return [
        ping(
            vehicle_id,
            start + timedelta(seconds=second),
            x0_m + speed_mps * second,
            speed_mps,
            **fields,
        )
        for second in range(seconds)
    ]


def store_pings_sql(connection: Connection, pings: list[dict[str, Any]]) -> None:
    """Store ping payloads as rows, map-matched like the server does (until ingest lands)."""
    geometry = seed_geometry()
    located = geometry.locate([p["lat"] for p in pings], [p["lon"] for p in pings])
    rows = []
    for payload, x_m, on in zip(pings, located.x_m, located.on_corridor, strict=True):
        row = {RENAMED.get(name, name): value for name, value in payload.items()}
        row["ts"] = datetime.fromisoformat(payload["ts"])
        row["x_m"] = float(x_m) if on else None
        rows.append(row)
    connection.execute(insert(VehiclePing), rows)


RENAMED = {
    "acc_engaged": "is_acc_engaged",
    "controller_engaged": "is_controller_engaged",
    "lead_present": "is_lead_present",
}
