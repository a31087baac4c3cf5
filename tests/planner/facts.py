"""Write INRIX readings and pings straight into the warehouse for the planner's tests."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from datetime import datetime, timedelta

import numpy as np
from sqlalchemy import Engine, text

from app.seed import seed_corridor_document

CORRIDOR = "I-24-WB"
SEED = seed_corridor_document()
INRIX_CODES = [segment["xd_code"] for segment in SEED["inrix_segments"]]


def inrix_snapshot(
    engine: Engine,
    measured_at: datetime,
    speeds_mps: Sequence[float],
    received_at: datetime | None = None,
    scores: Mapping[str, int] | None = None,
    fetched_at: datetime | None = None,
    **by_code: float,
) -> None:
    """One INRIX minute: a speed per corridor segment in order (overrides by code), with the
    INRIX score of the codes in `scores` (the others send none)."""
    speeds = dict(zip(INRIX_CODES, speeds_mps, strict=True)) | by_code
    readings(engine, measured_at, speeds, received_at, scores, fetched_at)


def readings(
    engine: Engine,
    measured_at: datetime,
    speeds_mps: Mapping[str, float],
    received_at: datetime | None = None,
    scores: Mapping[str, int] | None = None,
    fetched_at: datetime | None = None,
) -> None:
    """Some segments' readings of one INRIX minute, by code, stored at `received_at` (the
    minute itself unless given) from an answer fetched at `fetched_at` (unknown unless given)."""
    with engine.begin() as connection:
        connection.execute(
            text(
                "INSERT INTO fact_inrix_estimate (corridor_id, xd_code, measured_at, speed_mps, "
                "received_at, fetched_at, score) VALUES (:corridor, :code, :measured_at, "
                ":speed, :received_at, :fetched_at, :score)"
            ),
            [
                {
                    "corridor": CORRIDOR,
                    "code": code,
                    "measured_at": measured_at,
                    "speed": speed,
                    "received_at": received_at or measured_at,
                    "fetched_at": fetched_at,
                    "score": (scores or {}).get(code),
                }
                for code, speed in speeds_mps.items()
            ],
        )


def standing_slowdown(slow_mps: float = 7.0) -> list[float]:
    """Free flow at 29 m/s with a slowdown over segments SF-I24WB-11 to -14 (8.25-9.7 km)."""
    speeds = [29.0] * len(INRIX_CODES)
    for code in ("SF-I24WB-11", "SF-I24WB-12", "SF-I24WB-13", "SF-I24WB-14"):
        speeds[INRIX_CODES.index(code)] = slow_mps
    return speeds


def pings(
    engine: Engine,
    vehicle_id: str,
    end: datetime,
    x_m: Sequence[float | None],
    speed_mps: float | Sequence[float],
    lane: int | None = None,
    *,
    engaged: bool | None = None,
    lead_present: bool | None = None,
) -> None:
    """One ping a second ending at `end`, at the given positions (None = off the corridor),
    with the controller's engagement and the radar's lead flag as the car sent them."""
    count = len(x_m)
    speeds = np.broadcast_to(np.asarray(speed_mps, dtype=float), (count,))
    rows = [
        {
            "vehicle": vehicle_id,
            "ts": end - timedelta(seconds=count - 1 - index),
            "x_m": position,
            "speed": float(speeds[index]),
            "lane": lane,
            "engaged": engaged,
            "lead": lead_present,
        }
        for index, position in enumerate(x_m)
    ]
    with engine.begin() as connection:
        connection.execute(
            text(
                "INSERT INTO fact_vehicle_ping (vehicle_id, ts, lat, lon, speed_mps, x_m, lane, "
                "is_controller_engaged, is_lead_present) "
                "VALUES (:vehicle, :ts, 36.0, -86.6, :speed, :x_m, :lane, :engaged, :lead)"
            ),
            rows,
        )


def move_to_eastbound(engine: Engine, vehicle_id: str) -> None:
    """Open an eastbound corridor and move the vehicle onto it (a roster change of corridor)."""
    with engine.begin() as connection:
        connection.execute(
            text(
                "INSERT INTO dim_corridor (corridor_id, name, direction, lanes, length_m, "
                "speed_limit_mps, min_target_speed_mps) "
                "VALUES ('I-24-EB', 'I-24 eastbound', 'EB', 4, 6000, 31.3, 4.5)"
            )
        )
        connection.execute(
            text("UPDATE dim_vehicle SET corridor_id = 'I-24-EB' WHERE vehicle_id = :vehicle"),
            {"vehicle": vehicle_id},
        )
