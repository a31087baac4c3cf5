"""Alembic migrations: the only way the warehouse schema is created or changed."""
