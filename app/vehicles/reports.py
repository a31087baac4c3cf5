"""A vehicle's status reports (piStatus) and its configuration, for the vehicle-facing API."""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import select
from sqlalchemy.dialects.postgresql import insert
from sqlalchemy.ext.asyncio import AsyncSession

from app.core.config import Settings
from app.models import Vehicle, VehicleStatus
from contract.vehicles import ControllerConfig, VehicleConfig, VehicleStatusReport

# The API keeps the interface's names; the warehouse names booleans is_*/has_*.
STATUS_COLUMNS = {
    "can_ok": "is_can_ok",
    "gps_fix": "has_gps_fix",
    "acc_available": "is_acc_available",
    "controller_running": "is_controller_running",
    "ups_on_battery": "is_ups_on_battery",
}


async def vehicle_exists(session: AsyncSession, vehicle_id: str) -> bool:
    """True when the roster knows the vehicle, which then stays until the transaction ends.

    The row is locked FOR KEY SHARE (what the report's foreign key takes anyway, so no update of
    the car's config waits on it): an operator deleting the car in SQL meanwhile waits for the
    report to be stored, and a delete already under way is waited for and the car then found
    unknown. A plain read let the delete in between, and the insert's foreign-key violation
    answered 500.
    """
    found = await session.scalar(
        select(Vehicle.vehicle_id)
        .where(Vehicle.vehicle_id == vehicle_id)
        .with_for_update(read=True, key_share=True)
    )
    return found is not None


async def store_status(
    session: AsyncSession, vehicle_id: str, report: VehicleStatusReport, received_at: datetime
) -> bool:
    """Store a report; False when this (vehicle, ts) was already stored."""
    values = {STATUS_COLUMNS.get(name, name): value for name, value in report.model_dump().items()}
    statement = (
        insert(VehicleStatus)
        .values(vehicle_id=vehicle_id, received_at=received_at, **values)
        .on_conflict_do_nothing(index_elements=["vehicle_id", "ts"])
        .returning(VehicleStatus.ts)
    )
    return (await session.execute(statement)).first() is not None


async def vehicle_config(
    session: AsyncSession, vehicle_id: str, settings: Settings
) -> VehicleConfig | None:
    """What the vehicle should run, or None for an unknown vehicle."""
    vehicle = await session.get(Vehicle, vehicle_id)
    if vehicle is None:
        return None
    return VehicleConfig(
        vehicle_id=vehicle.vehicle_id,
        make=vehicle.make,
        model=vehicle.model,
        year=vehicle.year,
        actuation=vehicle.actuation,
        corridor_id=vehicle.corridor_id,
        route=vehicle.route,
        assigned_lane=vehicle.assigned_lane,
        controller=ControllerConfig(name=vehicle.controller_name, params=vehicle.controller_params),
        active=vehicle.is_active,
        in_maintenance=vehicle.is_in_maintenance,
        ping_period_s=settings.agent_ping_period_s,
        status_period_s=settings.agent_status_period_s,
        plan_poll_s=settings.agent_plan_poll_s,
        stale_plan_after_s=settings.agent_stale_plan_after_s,
        config_version=vehicle.config_version,
    )
