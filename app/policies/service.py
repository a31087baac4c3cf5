"""Storing and reading policies (no HTTP here: the API and the CLI share it).

A policy is the `.npz` an RL controller evaluates on the car (vehicle_agent/controllers/policy.py)
and the manifest `smoothfleet sim train` wrote beside it. It is stored once per sha256 of its
bytes: uploading the same file again changes nothing. Before it is kept it must be what it
claims to be: the manifest's `sha256` is the file's, and the file loads as a policy of the
controller its manifest's `actuation` names, the same check the car makes before use.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

from sqlalchemy import Insert, Select, select, update
from sqlalchemy.dialects.postgresql import insert
from sqlalchemy.ext.asyncio import AsyncSession
from sqlalchemy.orm import Session

from app.models import Policy, Vehicle
from contract.controllers import POLICY_SHA256_PATTERN, RL_CONTROLLERS
from contract.values import storable_text
from vehicle_agent.controllers.policy import PolicyFileError, read_policy
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES

_SHA256 = re.compile(POLICY_SHA256_PATTERN)


class PolicyError(ValueError):
    """An upload that is not a usable policy: `field` (`policy`, `manifest`, `manifest.sha256`,
    ...) and `reason`; the message says both."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


class ManifestConflict(ValueError):
    """The same policy bytes are stored already, with another manifest."""


@dataclass(frozen=True)
class CheckedPolicy:
    """An upload that passed every check, ready to store."""

    sha256: str
    controller: str
    manifest: dict[str, Any]
    content: bytes


def read_manifest(document: bytes | str) -> object:
    """A manifest's JSON, or PolicyError("manifest", why).

    Python's JSON writer puts NaN and Infinity where a figure was not measured, and its reader
    takes them back, but they are no JSON: PostgreSQL refuses them, and the upload ended in a
    database error naming no field. They are refused here, with what to write instead, as are
    numbers no float holds (1e400, an integer of 400 digits: a re-upload compares the
    manifests as floats) and text PostgreSQL cannot store (NUL, a lone surrogate), each named
    by where it is."""

    def no_number(constant: str) -> object:
        raise PolicyError(
            "manifest",
            f"{constant} is no JSON number and cannot be stored (write null for a figure that "
            "was not measured)",
        )

    def finite_float(text: str) -> float:
        value = float(text)
        if not math.isfinite(value):
            raise _beyond_a_float(text)
        return value

    def float_sized_integer(text: str) -> int:
        # A longer integer is beyond a float's range whatever its digits; int() would refuse
        # one over 4,300 digits with a ValueError of its own.
        if len(text.lstrip("-")) > _FLOAT_DIGITS or abs(int(text)) > sys.float_info.max:
            raise _beyond_a_float(text)
        return int(text)

    try:
        manifest = json.loads(
            document,
            parse_constant=no_number,
            parse_float=finite_float,
            parse_int=float_sized_integer,
        )
        _check_text(manifest, "manifest")  # as deep as the reader went, within the same catch
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise PolicyError("manifest", f"not JSON ({error})") from None
    except RecursionError:
        raise PolicyError("manifest", "nested too deeply to read") from None
    return manifest


# Digits of the largest float (1.8e308): an integer with more is beyond it.
_FLOAT_DIGITS = 309


def _beyond_a_float(number: str) -> PolicyError:
    """The error for a number no float holds, quoting it (a 5,000-digit one by its start and
    length)."""
    quoted = number if len(number) <= 24 else f"{number[:12]}... ({len(number)} characters)"
    return PolicyError("manifest", f"the number {quoted} is beyond a float's range")


def _check_text(value: object, where: str) -> None:
    """PolicyError naming the first key or string of `value` PostgreSQL cannot store."""
    if isinstance(value, str):
        try:
            storable_text(value)
        except ValueError as error:
            raise PolicyError(where, str(error)) from None
    elif isinstance(value, dict):
        for key, item in value.items():
            try:
                storable_text(key)
            except ValueError as error:
                raise PolicyError(where, f"a key: {error}") from None
            _check_text(item, f"{where}.{key}")
    elif isinstance(value, list):
        for index, item in enumerate(value):
            _check_text(item, f"{where}.{index}")


def check_policy(content: bytes, manifest: object, controller: str | None = None) -> CheckedPolicy:
    """The upload as a policy of `rl_<manifest actuation>`, or PolicyError naming what is wrong.

    `controller`, when given, must be the one the manifest's actuation implies.
    """
    if not isinstance(manifest, Mapping):
        raise PolicyError("manifest", "must be a JSON object (the manifest sim train wrote)")
    claimed = manifest.get("sha256")
    if not isinstance(claimed, str) or not _SHA256.match(claimed):
        raise PolicyError("manifest.sha256", "must be the file's sha256 as 64 lowercase hex digits")
    actual = hashlib.sha256(content).hexdigest()
    if claimed != actual:
        raise PolicyError(
            "manifest.sha256", f"the manifest names {claimed}, the file's sha256 is {actual}"
        )
    actuation = manifest.get("actuation")
    named = {actuation_: name for name, actuation_ in RL_CONTROLLERS.items()}
    if not isinstance(actuation, str) or actuation not in named:
        raise PolicyError("manifest.actuation", f"must be one of {', '.join(sorted(named))}")
    implied = named[actuation]
    if controller is not None and controller not in RL_CONTROLLERS:
        raise PolicyError(
            "controller", f"{controller!r} is no RL controller: one of {', '.join(RL_CONTROLLERS)}"
        )
    if controller is not None and controller != implied:
        raise PolicyError(
            "controller", f"the manifest is of an {actuation} policy ({implied}), not {controller}"
        )
    try:
        read_policy(content, RL_CONTROLLERS[implied], "policy")
    except PolicyFileError as error:
        raise PolicyError("policy", error.reason) from None
    return CheckedPolicy(actual, implied, dict(manifest), content)


def _insert(checked: CheckedPolicy, uploaded_by: str) -> Insert:
    return (
        insert(Policy)
        .values(
            policy_sha256=checked.sha256,
            controller=checked.controller,
            manifest=checked.manifest,
            content=checked.content,
            size_bytes=len(checked.content),
            uploaded_by=uploaded_by,
        )
        .on_conflict_do_nothing(index_elements=["policy_sha256"])
        .returning(Policy.policy_sha256)
    )


def _by_sha256(sha256: str) -> Select[Policy]:
    return select(Policy).where(Policy.policy_sha256 == sha256)


def _as_stored(value: Any) -> Any:
    """A manifest value as JSONB gives it back, for comparing: JSONB keeps a number as an exact
    decimal, so a float like 1e23 comes back as the integer 10**23, unequal to the float that
    was sent. Every number is compared as a float (booleans stay booleans)."""
    if isinstance(value, dict):
        return {key: _as_stored(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_as_stored(item) for item in value]
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    return value


def _same_manifest(checked: CheckedPolicy, stored: Policy) -> None:
    """An upload of bytes already stored is a no-op only with the manifest stored with them."""
    if _as_stored(stored.manifest) != _as_stored(checked.manifest):
        raise ManifestConflict(
            f"policy {checked.sha256} is stored already, with another manifest "
            f"(uploaded {stored.uploaded_at:%Y-%m-%d %H:%M} UTC by {stored.uploaded_by})"
        )


async def store_policy(
    session: AsyncSession, checked: CheckedPolicy, uploaded_by: str
) -> tuple[Policy, bool]:
    """Store a checked policy; (its row, True when it was new). Idempotent on the bytes."""
    created = await session.scalar(_insert(checked, uploaded_by)) is not None
    stored = await session.scalar(_by_sha256(checked.sha256))
    assert stored is not None, "inserted, or the row the insert met"
    if not created:
        _same_manifest(checked, stored)
    return stored, created


def store_policy_sync(
    session: Session, checked: CheckedPolicy, uploaded_by: str
) -> tuple[Policy, bool]:
    """`store_policy` for the command line's synchronous session."""
    created = session.scalar(_insert(checked, uploaded_by)) is not None
    stored = session.scalar(_by_sha256(checked.sha256))
    assert stored is not None, "inserted, or the row the insert met"
    if not created:
        _same_manifest(checked, stored)
    return stored, created


async def list_policies(session: AsyncSession) -> Sequence[Policy]:
    """Every stored policy, newest upload first (without the files)."""
    return (await session.scalars(select(Policy).order_by(Policy.uploaded_at.desc()))).all()


def list_policies_sync(session: Session) -> Sequence[Policy]:
    """`list_policies` for the command line."""
    return session.scalars(select(Policy).order_by(Policy.uploaded_at.desc())).all()


async def policy_file(session: AsyncSession, sha256: str) -> bytes | None:
    """The policy's bytes, or None when the server does not hold it."""
    return await session.scalar(select(Policy.content).where(Policy.policy_sha256 == sha256))


async def policy_manifest(session: AsyncSession, sha256: str) -> dict[str, Any] | None:
    """The policy's manifest, or None when the server does not hold it."""
    return await session.scalar(select(Policy.manifest).where(Policy.policy_sha256 == sha256))


async def policy_controller(session: AsyncSession, sha256: str) -> str | None:
    """The controller a stored policy is for (`rl_acc` / `rl_accel`), or None if not stored."""
    return await session.scalar(select(Policy.controller).where(Policy.policy_sha256 == sha256))


@cache
def bundled_policy_sha256(controller: str) -> str | None:
    """The sha256 of the policy the agent package ships for an RL controller, which a car
    assigned `controller` without a policy named runs (None for any other controller)."""
    if controller not in RL_CONTROLLERS:
        return None
    return hashlib.sha256((BUNDLED_POLICIES / f"{controller}.npz").read_bytes()).hexdigest()


def store_shipped_policy(session: Session, controller: str, uploaded_by: str) -> Policy:
    """Store the policy the agent package ships for `controller` (`rl_acc` / `rl_accel`, in
    `vehicle_agent/controllers/policies/`) with the manifest written beside it, checked as an
    upload is, so that a car can be assigned it by sha256 and download it from here.

    Idempotent on the bytes; ManifestConflict when they are stored already with another manifest.
    """
    path = BUNDLED_POLICIES / f"{controller}.npz"
    manifest = json.loads(path.with_suffix(".json").read_text(encoding="utf-8"))
    checked = check_policy(path.read_bytes(), manifest, controller)
    stored, _ = store_policy_sync(session, checked, uploaded_by)
    return stored


def assign_shipped_policies(session: Session) -> dict[str, str]:
    """Store the policies the agent package ships (`vehicle_agent/controllers/policies/`) and
    assign each to every car of its actuation (`smoothfleet demo --rl`); controller -> sha256.

    Every car is RL-capable: `acc` cars run `rl_acc`, `accel` cars `rl_accel`; their lanes and
    routes stay as they are, and their config version is bumped like any assignment change.
    """
    assigned: dict[str, str] = {}
    for controller, actuation in RL_CONTROLLERS.items():
        stored = store_shipped_policy(session, controller, "demo")
        session.execute(
            update(Vehicle)
            .where(Vehicle.actuation == actuation)
            .values(
                controller_name=controller,
                controller_params={"policy_sha256": stored.policy_sha256},
                config_version=Vehicle.config_version + 1,
            )
        )
        assigned[controller] = stored.policy_sha256
    return assigned
