"""Policies are versioned artefacts: stored by sha256 with their manifest; pings and status
reports carry the hash of the policy the car runs.

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-30 15:40:00+00:00

`dim_policy` holds each uploaded policy file (bytea, tens of kB) with its training manifest
(jsonb), keyed by the file's sha256. `fact_vehicle_ping.policy_sha256` and
`fact_vehicle_status.policy_sha256` say which policy a car ran, so two policies run on two halves
of the fleet can be compared in SQL afterwards (docs/analytics.md). No foreign key from the facts:
ingest never waits on the dimension, and a car may report a policy it carries itself.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op
from sqlalchemy.dialects import postgresql

revision: str = "0007"
down_revision: str | None = "0006"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "dim_policy",
        sa.Column("policy_sha256", sa.Text(), nullable=False),
        sa.Column("controller", sa.Text(), nullable=False),
        sa.Column("manifest", postgresql.JSONB(astext_type=sa.Text()), nullable=False),
        sa.Column("content", sa.LargeBinary(), nullable=False),
        sa.Column("size_bytes", sa.Integer(), nullable=False),
        sa.Column("uploaded_by", sa.Text(), nullable=False),
        sa.Column(
            "uploaded_at",
            sa.DateTime(timezone=True),
            server_default=sa.text("now()"),
            nullable=False,
        ),
        sa.CheckConstraint(
            "policy_sha256 ~ '^[0-9a-f]{64}$'", name=op.f("ck_dim_policy_sha256_format")
        ),
        sa.CheckConstraint(
            "controller IN ('rl_acc', 'rl_accel')", name=op.f("ck_dim_policy_controller_kind")
        ),
        sa.CheckConstraint(
            "octet_length(content) = size_bytes", name=op.f("ck_dim_policy_size_matches")
        ),
        sa.PrimaryKeyConstraint("policy_sha256", name=op.f("pk_dim_policy")),
        comment="One row per policy artefact (file bytes + manifest), keyed by its sha256.",
    )
    op.add_column("fact_vehicle_ping", sa.Column("policy_sha256", sa.Text(), nullable=True))
    op.add_column("fact_vehicle_status", sa.Column("policy_sha256", sa.Text(), nullable=True))


def downgrade() -> None:
    op.drop_column("fact_vehicle_status", "policy_sha256")
    op.drop_column("fact_vehicle_ping", "policy_sha256")
    op.drop_table("dim_policy")
