"""`GET /api/v1/corridors/{corridor_id}`: the geometry, with an ETag (it rarely changes)."""

from __future__ import annotations

import hashlib
from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Request, Response

from app.auth import AuthDep
from app.core.errors import error_responses
from app.core.sessions import SessionDep
from app.corridors.schemas import CorridorOut
from app.corridors.service import corridor_geometry
from contract.values import StorableText

router = APIRouter(prefix="/api/v1", tags=["corridors"])


@router.get(
    "/corridors/{corridor_id}",
    response_model=CorridorOut,
    responses={
        304: {"description": "unchanged since If-None-Match"},
        **error_responses(401, 404, 503),
    },
)
async def get_corridor(
    corridor_id: Annotated[StorableText, Path()],
    request: Request,
    principal: AuthDep,
    session: SessionDep,
) -> Response:
    """Segments with postmiles, x_m, lat/lon and lanes, plus the legal target-speed range."""
    corridor = await corridor_geometry(session, corridor_id)
    if corridor is None:
        raise HTTPException(404, f"unknown corridor {corridor_id}")
    body = corridor.model_dump_json().encode()
    etag = '"' + hashlib.sha256(body).hexdigest()[:32] + '"'
    if etag in request.headers.get("if-none-match", ""):
        return Response(status_code=304, headers={"ETag": etag})
    return Response(body, media_type="application/json", headers={"ETag": etag})
