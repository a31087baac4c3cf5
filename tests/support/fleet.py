"""Vehicle data for tests, written as the API's pings and status reports.

Tests describe a drive by position along the corridor (x_m) because hand-worked values (Edie
boxes, plan segments) are about positions; `ping()` turns that into the GPS fix a car would send,
so the server's own map-matching puts it back at x_m.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from functools import lru_cache
from typing import Any

import httpx

from app.seed import seed_corridor_document
from contract.corridor import CorridorGeometry
from tests.support.tokens import bearer

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


def post_pings(client: httpx.Client, token: str, pings: list[dict[str, Any]]) -> None:
    """Post pings through the ingest API in batches; every one must be accepted."""
    for first in range(0, len(pings), 1000):
        batch = pings[first : first + 1000]
        response = client.post("/api/v1/pings", json={"pings": batch}, headers=bearer(token))
        assert response.status_code == 200, response.text
        assert response.json()["accepted"] == len(batch), response.text


def post_status(client: httpx.Client, token: str, vehicle_id: str, **report: Any) -> None:
    """Post one piStatus report (`ts` as a datetime) through the API."""
    body = {
        name: value.isoformat() if isinstance(value, datetime) else value
        for name, value in report.items()
    }
    response = client.post(
        f"/api/v1/vehicles/{vehicle_id}/status", json=body, headers=bearer(token)
    )
    assert response.status_code == 200, response.text


def post_inrix(
    client: httpx.Client,
    token: str,
    measured_at: datetime,
    speeds_mph: dict[str, float],
    closed: str | None = None,
) -> None:
    """Post one INRIX snapshot (segment code -> speed in mph, real-time score) via the feed API;
    the segment `closed` is reported closed."""
    document = {
        "result": {
            "segmentspeeds": [
                {
                    "timestamp": measured_at.isoformat(),
                    "segments": [
                        {
                            "code": code,
                            "type": "XDS",
                            "speed": speed,
                            "score": 30,
                            "segmentClosed": code == closed,
                        }
                        for code, speed in speeds_mph.items()
                    ],
                }
            ]
        }
    }
    response = client.post("/api/v1/feeds/inrix", json=document, headers=bearer(token))
    assert response.status_code == 200, response.text


def healthy_status(
    ts: datetime, controller: str = "microaccel_acc", **changes: Any
) -> dict[str, Any]:
    """A piStatus report that passes every readiness check (fields overridden by `changes`)."""
    report: dict[str, Any] = {
        "ts": ts,
        "agent_version": "1.0.0",
        "uptime_s": 3600.0,
        "can_ok": True,
        "can_msgs_per_s": 1800.0,
        "gps_fix": True,
        "gps_satellites": 11,
        "acc_available": True,
        "controller": controller,
        "controller_running": True,
        "plan_age_s": 12.0,
        "spool_backlog": 0,
        "disk_free_mb": 12000.0,
        "cpu_temp_c": 55.0,
        "ups_on_battery": False,
        "server_rtt_ms": 80.0,
    }
    report.update(changes)
    return report
