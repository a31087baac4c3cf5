"""Schemathesis over the whole OpenAPI, with a valid token and without one.

Every operation gets generated valid and invalid requests (examples, coverage of boundaries and
fuzzing). Checks: no 5xx, every status code documented, every body in its documented shape
(errors: `{"detail": ...}`). The run's seed is fixed so CI is repeatable; run the same command
without `--seed` for fresh cases (see docs/operations.md).
"""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from sqlalchemy import Engine

from app.core.config import load_settings
from app.plans.jobs import run_planner
from tests.planner.facts import inrix_snapshot, standing_slowdown
from tests.support.servers import live_server
from tests.support.tokens import issue

CHECKS = ",".join(
    (
        "not_a_server_error",
        "status_code_conformance",
        "content_type_conformance",
        "response_schema_conformance",
    )
)
SEED = "20261123"
SECONDS_PER_RUN = "40"


@pytest.fixture
def api_with_a_plan(seeded_database_url: str, seeded_engine: Engine) -> Iterator[str]:
    """The live API over a seeded warehouse with a published plan (so plan reads are 200)."""
    now = datetime.now(UTC).replace(microsecond=0)
    for minutes_ago in range(6, 1, -1):
        inrix_snapshot(seeded_engine, now - timedelta(minutes=minutes_ago), standing_slowdown())
    settings = load_settings(database_url=seeded_database_url, plan_valid_for_s=900)
    (outcome,) = run_planner(seeded_engine, settings)
    assert outcome.status == "published", outcome.reason
    with live_server(
        seeded_database_url,
        planner_enabled=False,
        plan_valid_for_s=900,
        rate_limit_per_token_per_s=0,  # limits have their own tests; here, reach the logic
    ) as base:
        yield base


def fuzz(base: str, workdir: Path, *headers: str) -> subprocess.CompletedProcess[str]:
    command = [
        str(Path(sys.executable).parent / "schemathesis"),
        "run",
        f"{base}/openapi.json",
        "--checks",
        CHECKS,
        "--phases",
        "examples,coverage,fuzzing",
        "--max-time",
        SECONDS_PER_RUN,
        "--seed",
        SEED,
        "--workers",
        "1",
        "--generation-database",
        "none",
        "--no-color",
        *[part for header in headers for part in ("-H", header)],
    ]
    return subprocess.run(
        command, cwd=workdir, capture_output=True, text=True, timeout=600, check=False
    )


def cases_passed(report: str) -> int:
    """How many generated cases passed every check (all of them, or the run failed)."""
    found = re.search(r"(\d+) generated, (\d+) passed", report)
    assert found, report[-3000:]
    generated, passed = int(found[1]), int(found[2])
    assert generated == passed, report[-3000:]
    return passed


@pytest.mark.slow
def test_fuzzing_with_an_admin_token_finds_no_server_error_and_no_shape_violation(
    api_with_a_plan: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    token = issue(seeded_engine, "admin")
    result = fuzz(api_with_a_plan, tmp_path, f"Authorization: Bearer {token}")
    assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]
    assert cases_passed(result.stdout) >= 500


@pytest.mark.slow
def test_fuzzing_without_a_token_is_only_ever_refused_in_the_documented_shape(
    api_with_a_plan: str, tmp_path: Path
) -> None:
    result = fuzz(api_with_a_plan, tmp_path)
    assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]
    assert cases_passed(result.stdout) >= 500
    assert "returned only 401/403 responses" in result.stdout
