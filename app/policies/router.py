"""Policy API: upload (operator or admin), list, and download by sha256 (docs/interfaces.md,
"Policies"). A vehicle downloads the policy its assignment names over this authenticated API.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, File, Form, HTTPException, Path, Response, UploadFile

from app.auth import AuthDep, OperatorDep, ViewerDep
from app.core.errors import error_responses
from app.core.sessions import SessionDep
from app.policies.schemas import PolicyOut, PolicyUploadOut, policy_out
from app.policies.service import (
    ManifestConflict,
    PolicyError,
    check_policy,
    list_policies,
    policy_file,
    policy_manifest,
    read_manifest,
    store_policy,
)
from contract.controllers import POLICY_SHA256_PATTERN, RL_CONTROLLERS

router = APIRouter(prefix="/api/v1", tags=["policies"])

Sha256 = Annotated[
    str, Path(pattern=POLICY_SHA256_PATTERN, description="the policy file's sha256 (hex)")
]


def _rejected(field: str, reason: str) -> HTTPException:
    """A 422 in FastAPI's shape for a rejected field (docs/interfaces.md, "Errors")."""
    return HTTPException(
        422, [{"loc": ["body", *field.split(".")], "msg": reason, "type": "value_error"}]
    )


def _may_read(role: str) -> None:
    if role == "feed":
        raise HTTPException(403, "a feed token may not read policies")


@router.post(
    "/policies",
    status_code=201,
    responses={
        **error_responses(401, 403, 409, 413, 422, 503),
        200: {"model": PolicyUploadOut, "description": "the same file was stored already"},
    },
    summary="Upload a policy file with its manifest",
)
async def post_policy(
    principal: OperatorDep,
    session: SessionDep,
    response: Response,
    policy: Annotated[UploadFile, File(description="the policy .npz (sim train's output)")],
    manifest: Annotated[UploadFile, File(description="its manifest (the .json beside it)")],
    controller: Annotated[
        str | None,
        Form(
            description="rl_acc or rl_accel; checked against the manifest's actuation",
            json_schema_extra={"enum": list(RL_CONTROLLERS)},
        ),
    ] = None,
) -> PolicyUploadOut:
    """Store a policy by its sha256 (operator or admin): 201 when new, 200 when the same file
    was stored already with the same manifest, 409 with another one. 422 when the manifest's
    `sha256` is not the file's, or the file is not a policy of the manifest's controller."""
    content = await policy.read()
    try:
        document = read_manifest(await manifest.read())
        checked = check_policy(content, document, controller)
        stored, created = await store_policy(session, checked, f"token {principal.token_id}")
    except PolicyError as error:
        raise _rejected(error.field, error.reason) from None
    except ManifestConflict as error:
        raise HTTPException(409, str(error)) from None
    response.status_code = 201 if created else 200
    return PolicyUploadOut(**policy_out(stored).model_dump(), created=created)


@router.get("/policies", responses=error_responses(401, 403, 503), summary="Stored policies")
async def get_policies(principal: ViewerDep, session: SessionDep) -> list[PolicyOut]:
    """Every stored policy, newest first (ops token)."""
    return [policy_out(policy) for policy in await list_policies(session)]


@router.get(
    "/policies/{sha256}",
    response_class=Response,
    responses={
        **error_responses(401, 403, 404, 503),
        200: {
            "content": {
                "application/octet-stream": {"schema": {"type": "string", "format": "binary"}}
            },
            "description": "the policy file, byte for byte",
        },
    },
    summary="Download a policy file",
)
async def get_policy(sha256: Sha256, principal: AuthDep, session: SessionDep) -> Response:
    """The policy's bytes (vehicle or ops token). The car checks the sha256 before use; the
    file never changes, so it may be cached for good."""
    _may_read(principal.role)
    content = await policy_file(session, sha256)
    if content is None:
        raise HTTPException(404, f"no policy {sha256} on this server")
    return Response(
        content,
        media_type="application/octet-stream",
        headers={"ETag": f'"{sha256}"', "Cache-Control": "private, max-age=31536000, immutable"},
    )


@router.get(
    "/policies/{sha256}/manifest",
    responses=error_responses(401, 403, 404, 503),
    summary="A policy's manifest",
)
async def get_policy_manifest(
    sha256: Sha256, principal: AuthDep, session: SessionDep
) -> dict[str, Any]:
    """The manifest stored with the policy (training dates, seed, hyperparameters, KPIs)."""
    _may_read(principal.role)
    manifest = await policy_manifest(session, sha256)
    if manifest is None:
        raise HTTPException(404, f"no policy {sha256} on this server")
    return manifest
