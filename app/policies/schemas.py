"""Policy API bodies: a stored policy as the API lists it."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import BaseModel, Field

from app.models import Policy


class PolicyOut(BaseModel):
    """A stored policy: its sha256, controller, size, who uploaded it and when."""

    sha256: str = Field(description="sha256 of the policy file: the name an assignment uses")
    controller: str = Field(examples=["rl_acc"])
    size_bytes: int
    uploaded_by: str
    uploaded_at: datetime
    trained_at: str | None = Field(None, description="from the manifest")
    seed: int | None = Field(None, description="from the manifest")
    source_commit: str | None = Field(None, description="from the manifest")


class PolicyUploadOut(PolicyOut):
    """The answer to an upload: the policy, and whether this upload stored it."""

    created: bool = Field(description="false: the same file was stored already")


def _text(manifest: dict[str, Any], key: str) -> str | None:
    value = manifest.get(key)
    return value if isinstance(value, str) else None


def policy_out(policy: Policy) -> PolicyOut:
    """The API view of a stored policy (a few manifest fields; the whole one has its own URL)."""
    manifest = policy.manifest
    seed = manifest.get("seed")
    return PolicyOut(
        sha256=policy.policy_sha256,
        controller=policy.controller,
        size_bytes=policy.size_bytes,
        uploaded_by=policy.uploaded_by,
        uploaded_at=policy.uploaded_at,
        trained_at=_text(manifest, "trained_at"),
        seed=seed if isinstance(seed, int) and not isinstance(seed, bool) else None,
        source_commit=_text(manifest, "source_commit"),
    )
