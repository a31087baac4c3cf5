"""Vehicle-facing API: pings, piStatus reports, the vehicle's config (docs/interfaces.md)."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Path, Request, Response

from app.auth import AuthDep, PingWriterDep, Principal, bearer_scheme
from app.core import metrics
from app.core.config import Settings
from app.core.errors import error_responses
from app.core.json_keys import RepeatedKeysRefused
from app.core.sessions import SessionDep
from app.ingest.http import reply_to_pings
from app.vehicles.reports import store_status, vehicle_config, vehicle_exists
from contract.vehicles import (
    MAX_PINGS_PER_BATCH,
    VEHICLE_ID_PATTERN,
    Ping,
    PingAnswer,
    StatusAnswer,
    VehicleConfig,
    VehicleStatusReport,
)

router = APIRouter(prefix="/api/v1", tags=["vehicles"], route_class=RepeatedKeysRefused)

VehicleId = Annotated[str, Path(pattern=VEHICLE_ID_PATTERN)]

STATUS_INVALID = (
    "the report breaks its schema, or its `ts` lies outside the server's window around now "
    "(see `ts`): the list of rejected fields, or a sentence naming `ts`"
)

_PING_SCHEMA = Ping.model_json_schema()
_PINGS_BODY: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {
                "schema": {
                    "anyOf": [
                        _PING_SCHEMA,
                        {
                            "type": "object",
                            "title": "PingBatch",
                            "properties": {
                                "pings": {
                                    "type": "array",
                                    # Each item is read on its own: a ping (schema Ping) is
                                    # stored, anything else rejected with its index while the
                                    # others are kept; so any item is acceptable here.
                                    "items": {"description": "a ping (Ping), read on its own"},
                                    "maxItems": MAX_PINGS_PER_BATCH,
                                }
                            },
                            "required": ["pings"],
                        },
                    ]
                }
            }
        },
    }
}


def _settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


def _may_act_for(principal: Principal, vehicle_id: str) -> None:
    if not principal.may_report_for(vehicle_id):
        raise HTTPException(403, f"{principal.token_words} may not act for vehicle {vehicle_id}")


@router.post(
    "/pings",
    response_model=PingAnswer,
    responses=error_responses(401, 403, 409, 413, 422, 503),
    openapi_extra=_PINGS_BODY,
    dependencies=[Depends(bearer_scheme)],
    summary="Post one ping or a batch of up to 1000",
)
async def post_pings(request: Request) -> Response:
    """Store the good pings, answering only after they are committed.

    Each bad ping is rejected with its index and reason while the good ones are kept; a resent
    ping (same vehicle_id and ts) counts as a duplicate. Vehicle, operator and admin tokens may
    post; a vehicle token only its own vehicle's pings: one foreign ping refuses the whole
    request (403) and nothing is stored. The server answers this path in app.ingest.asgi
    before routing; this declaration documents it and answers the same way.
    """
    reply = await reply_to_pings(
        request.app.state,
        request.headers.get("authorization"),
        await request.body(),
        request.headers.get("content-encoding"),
    )
    return Response(
        reply.body, status_code=reply.status, headers=reply.headers, media_type="application/json"
    )


@router.post(
    "/vehicles/{vehicle_id}/status",
    responses=error_responses(401, 403, 404, 413, 503, described={422: STATUS_INVALID}),
    summary="Post a piStatus report",
)
async def post_status(
    vehicle_id: VehicleId,
    report: VehicleStatusReport,
    request: Request,
    principal: PingWriterDep,
    session: SessionDep,
) -> StatusAnswer:
    """Store the report (idempotent on vehicle_id and ts); answered after the commit."""
    received_at = datetime.now(UTC)
    _may_act_for(principal, vehicle_id)
    settings = _settings(request)
    if report.ts > received_at + timedelta(seconds=settings.ping_max_future_s):
        raise HTTPException(422, f"ts is more than {settings.ping_max_future_s:g} s in the future")
    if report.ts < received_at - timedelta(days=settings.ping_retention_days):
        raise HTTPException(
            422, f"ts is older than the {settings.ping_retention_days}-day retention window"
        )
    if not await vehicle_exists(session, vehicle_id):
        raise HTTPException(404, f"unknown vehicle {vehicle_id}")
    stored = await store_status(session, vehicle_id, report, received_at)
    metrics.STATUS_REPORTS.labels("accepted" if stored else "duplicate").inc()
    return StatusAnswer(accepted=int(stored), duplicates=int(not stored))


@router.get(
    "/vehicles/{vehicle_id}/config",
    responses=error_responses(401, 403, 404, 503),
    summary="What the vehicle should run",
)
async def get_config(
    vehicle_id: VehicleId, request: Request, principal: AuthDep, session: SessionDep
) -> VehicleConfig:
    """The vehicle's make, actuation, assignment, controller and the agent's periods.

    A vehicle token reads only its own config; any ops token reads every vehicle's.
    """
    if principal.role == "feed" or (
        principal.role == "vehicle" and principal.vehicle_id != vehicle_id
    ):
        raise HTTPException(
            403, f"{principal.token_words} may not read the config of vehicle {vehicle_id}"
        )
    config = await vehicle_config(session, vehicle_id, _settings(request))
    if config is None:
        raise HTTPException(404, f"unknown vehicle {vehicle_id}")
    return config
