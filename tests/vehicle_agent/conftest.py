"""Fixtures for the vehicle agent's tests: one DBC cache for the session."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def dbc_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A cache directory for the generated opendbc DBCs, shared by the session's tests."""
    return tmp_path_factory.mktemp("dbc")
