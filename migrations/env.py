"""Alembic environment: runs against the connection handed in by app.migrate, or a URL."""

from __future__ import annotations

import re
from typing import Any

from alembic import context
from sqlalchemy import Connection, create_engine, pool

from app.core.db import sqlalchemy_url
from app.models import Base

# Daily ping partitions and the default partition are created by SQL functions, not by models.
PARTITION_TABLE = re.compile(r"^fact_vehicle_ping_(p\d{8}|default)$")


def include_object(
    obj: Any, name: str | None, type_: str, reflected: bool, compare_to: Any
) -> bool:
    """Leave partitions (made at run time) and views (made by SQL in migrations) out of checks."""
    if type_ == "table" and name is not None and PARTITION_TABLE.match(name):
        return False
    if type_ == "index" and reflected and compare_to is None and obj.table is not None:
        return not PARTITION_TABLE.match(obj.table.name)
    return True


def run_with(connection: Connection) -> None:
    context.configure(
        connection=connection,
        target_metadata=Base.metadata,
        include_object=include_object,
        compare_type=True,
    )
    with context.begin_transaction():
        context.run_migrations()


def main() -> None:
    config = context.config
    connection = config.attributes.get("connection")
    if connection is not None:
        run_with(connection)
        return
    url = config.get_main_option("sqlalchemy.url")
    if not url:
        raise SystemExit("migrations: no database URL (use `smoothfleet db upgrade`)")
    engine = create_engine(sqlalchemy_url(url), poolclass=pool.NullPool)
    with engine.connect() as connection:
        run_with(connection)


if context.is_offline_mode():
    raise SystemExit("offline (SQL script) migrations are not supported; run them against a server")
main()
