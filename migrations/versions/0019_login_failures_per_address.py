"""Failed dashboard logins are counted per (user, client address).

Revision ID: 0019
Revises: 0018
Create Date: 2026-12-05 16:00:00+00:00

The wait between login attempts was counted per account (`ops_user.failed_logins`) and checked
before the password: anyone who knew a username could keep its owner out with one wrong guess
every five minutes (security audit). The wait is now counted per (user, client address) in
`ops_login_failure`; `ops_user.failed_logins` stays the account's count over every address since
its last success (`smoothfleet users list`). No row: that address has not failed since its last
success. Waits running at the upgrade end with it (they were per account).
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0019"
down_revision: str | None = "0018"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "ops_login_failure",
        sa.Column("username", sa.Text(), nullable=False),
        sa.Column("client_address", sa.Text(), nullable=False),
        sa.Column("failures", sa.Integer(), nullable=False),
        sa.Column("last_failed_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["username"],
            ["ops_user.username"],
            name=op.f("fk_ops_login_failure_username_ops_user"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("username", "client_address", name=op.f("pk_ops_login_failure")),
        comment="Failed dashboard logins per (user, client address) since its last success.",
    )


def downgrade() -> None:
    op.drop_table("ops_login_failure")
