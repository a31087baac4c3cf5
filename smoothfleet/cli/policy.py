"""`smoothfleet policy upload | list`: trained policies as versioned artefacts on the server.

`upload FILE` stores a policy `.npz` with its manifest (by default the `.json` beside it, as
`smoothfleet sim train` writes them) under the file's sha256; an assignment then names it with
`{"policy_sha256": ...}` (docs/agent.md, "Policies").
"""

from __future__ import annotations

from pathlib import Path

import click

from contract.controllers import RL_CONTROLLERS
from smoothfleet.cli.common import CliError, console, database, settings


def read_upload(policy_file: Path, manifest_file: Path | None) -> tuple[bytes, object]:
    """The policy's bytes and its parsed manifest, or CliError naming the file at fault."""
    from app.policies.service import PolicyError, read_manifest

    manifest_file = manifest_file or policy_file.with_suffix(".json")
    try:
        content = policy_file.read_bytes()
    except OSError as error:
        raise CliError(f"policy: {policy_file}: {error.strerror or error}") from None
    try:
        manifest = read_manifest(manifest_file.read_bytes())
    except OSError as error:
        raise CliError(f"policy: manifest {manifest_file}: {error.strerror or error}") from None
    except PolicyError as error:
        raise CliError(f"policy: manifest {manifest_file}: {error.reason}") from None
    return content, manifest


@click.group("policy")
def policy() -> None:
    """Trained controller policies stored on the server by sha256."""


@policy.command("upload")
@click.argument("policy_file", type=click.Path(path_type=Path))
@click.option(
    "--manifest",
    "manifest_file",
    type=click.Path(path_type=Path),
    help="The policy's manifest (default: the .json beside FILE).",
)
@click.option(
    "--controller",
    type=click.Choice(list(RL_CONTROLLERS)),
    help="Check that the policy is for this controller.",
)
def policy_upload(policy_file: Path, manifest_file: Path | None, controller: str | None) -> None:
    """Store POLICY_FILE under its sha256 (idempotent: the same file again changes nothing)."""
    from app.core.db import make_sync_engine, session_scope
    from app.policies.service import ManifestConflict, PolicyError, check_policy, store_policy_sync

    content, manifest = read_upload(policy_file, manifest_file)
    try:
        checked = check_policy(content, manifest, controller)
    except PolicyError as error:
        raise CliError(f"policy: {policy_file}: {error}") from None
    with database(settings()) as url:
        engine = make_sync_engine(url)
        try:
            with session_scope(engine) as session:
                stored, created = store_policy_sync(session, checked, "cli")
                sha256, name = stored.policy_sha256, stored.controller
        except ManifestConflict as error:
            raise CliError(f"policy: {error}") from None
        finally:
            engine.dispose()
    state = "stored" if created else "already stored"
    console.print(f"{name} policy {sha256} {state}", soft_wrap=True)


@policy.command("list")
def policy_list() -> None:
    """The stored policies, newest first: one line each, the full sha256 first."""
    from app.core.db import make_sync_engine, session_scope
    from app.policies.service import list_policies_sync

    lines = []
    with database(settings()) as url:
        engine = make_sync_engine(url)
        try:
            with session_scope(engine) as session:
                for stored in list_policies_sync(session):
                    trained = stored.manifest.get("trained_at") or "?"
                    lines.append(
                        f"{stored.policy_sha256}  {stored.controller:<8}  "
                        f"{stored.size_bytes:>7} B  uploaded {stored.uploaded_at:%Y-%m-%d %H:%M} "
                        f"UTC by {stored.uploaded_by}  trained {trained}"
                    )
        finally:
            engine.dispose()
    for line in lines:
        console.print(line, soft_wrap=True, highlight=False)
    console.print(f"{len(lines)} policy(ies)")
