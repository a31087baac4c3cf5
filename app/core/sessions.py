"""The request's database session, as a FastAPI dependency (`SessionDep`).

Kept apart from `app.core.db` so that the command line and migrations, which use that module's
engines, do not import FastAPI.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import Depends, Request
from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker


async def get_session(request: Request) -> AsyncIterator[AsyncSession]:
    """FastAPI dependency: one session per request, committed when the handler succeeds."""
    factory: async_sessionmaker[AsyncSession] = request.app.state.sessionmaker
    async with factory() as session, session.begin():
        yield session


# scope="function" ends the dependency (and commits) before the response is sent, so a 200
# always means "committed" (FastAPI's default scope would commit after the response started).
SessionDep = Annotated[AsyncSession, Depends(get_session, scope="function")]
